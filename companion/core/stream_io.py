"""Writing a recorded stream folder and reading its truth files back."""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import cv2

from companion.core.frames import Frame
from companion.core.images import write_image
from companion.core.stream_format import (
    BOXES_HEADER,
    CAMERA_HEADER,
    CORNER_COLUMNS,
    FRAMES_HEADER,
    POSE_HEADER,
    RANGE_HEADER,
    TELEMETRY_HEADER,
    FrameTruth,
    StreamMeta,
    TruthBox,
    TruthCamera,
    TruthPose,
    box_row,
    camera_row,
    dumps_toml,
    meta_to_dict,
    open_csv,
    parse_box_row,
    parse_camera_row,
    parse_pose_row,
    pose_row,
)
from companion.errors import InputError

FRAMES_DIR = "frames"
VIDEO_NAME = "frames.mkv"
IMAGE_FORMATS = ("png", "jpg", "ffv1")


class StreamWriter:
    """Writes frames (and optional truth) into a new recorded stream folder.

    Frames go to ``frames/NNNNNN.<image_format>`` (``png``, lossless, or ``jpg``), or with
    ``ffv1`` into one lossless FFV1 video ``frames.mkv`` (rows ``frames.mkv#N``, N the
    0-based frame number in the video).  The CSVs are written as frames arrive and
    flushed on :meth:`close`.  ``stream.toml`` is written first, so a folder cut short
    by a crash is still readable up to its last complete row.  A folder that already holds
    a stream is refused unless ``overwrite``.
    """

    def __init__(
        self,
        folder: Path,
        meta: StreamMeta,
        image_format: str = "png",
        jpeg_quality: int = 95,
        overwrite: bool = False,
    ) -> None:
        if image_format not in IMAGE_FORMATS:
            raise InputError(f"image format must be png, jpg or ffv1, got {image_format!r}")
        self.folder = Path(folder)
        if (self.folder / "stream.toml").exists() and not overwrite:
            raise InputError(f"{self.folder}: already holds a stream (choose another --out)")
        (self.folder / FRAMES_DIR).mkdir(parents=True, exist_ok=True)
        self.meta = meta
        self.image_format = image_format
        self.jpeg_quality = jpeg_quality
        provenance = {"image_format": image_format, **dict(meta.provenance)}
        self.meta = replace(meta, provenance=provenance)
        (self.folder / "stream.toml").write_text(dumps_toml(meta_to_dict(self.meta)), "utf-8")
        self._files: dict[str, tuple[IO[str], Any]] = {}
        self._open("frames.csv", FRAMES_HEADER)
        self._video: cv2.VideoWriter | None = None
        if image_format == "ffv1":
            cam = meta.camera
            self._video = cv2.VideoWriter(str(self.folder / VIDEO_NAME),
                                          cv2.VideoWriter.fourcc(*"FFV1"), float(meta.fps),
                                          (cam.width, cam.height))
            if not self._video.isOpened():
                raise InputError(f"{self.folder}: OpenCV cannot write FFV1 video here")
        self.count = 0
        self._last_t_us: int | None = None

    def _open(self, name: str, header: tuple[str, ...]) -> Any:
        if name not in self._files:
            fh = (self.folder / name).open("w", newline="", encoding="utf-8")
            writer = csv.writer(fh, lineterminator="\n")
            writer.writerow(header)
            self._files[name] = (fh, writer)
        return self._files[name][1]

    def write(self, frame: Frame, truth: FrameTruth | None = None) -> None:
        """Append one frame (times must increase) and its truth."""
        cam = self.meta.camera
        if frame.size != (cam.width, cam.height):
            raise InputError(
                f"frame {frame.index}: size {frame.size} differs from the stream's "
                f"{cam.width}x{cam.height}"
            )
        if self._last_t_us is not None and frame.t_us <= self._last_t_us:
            raise InputError(f"frame {frame.index}: time {frame.t_us} us does not increase")
        if self._video is not None:
            name = f"{VIDEO_NAME}#{self.count}"
            self._video.write(frame.image)
        else:
            name = f"{FRAMES_DIR}/{frame.index:06d}.{self.image_format}"
            write_image(self.folder / name, frame.image, self.jpeg_quality)
        self._open("frames.csv", FRAMES_HEADER).writerow([frame.index, frame.t_us, name])
        self._last_t_us = frame.t_us
        self.count += 1
        if truth is not None:
            self._write_truth(frame, truth)

    def _write_truth(self, frame: Frame, truth: FrameTruth) -> None:
        boxes = self._open("truth_boxes.csv", BOXES_HEADER + CORNER_COLUMNS)
        for box in truth.boxes:
            boxes.writerow(box_row(frame.index, box))
        if truth.pose is not None:
            self._open("truth_pose.csv", POSE_HEADER).writerow(
                pose_row(frame.index, frame.t_us, truth.pose)
            )
        if truth.camera is not None:
            self._open("truth_camera.csv", CAMERA_HEADER).writerow(
                camera_row(frame.index, frame.t_us, truth.camera)
            )
        rng = "" if truth.range_m is None else f"{truth.range_m:.4f}"
        self._open("truth_range.csv", RANGE_HEADER).writerow([frame.index, frame.t_us, rng])

    def write_telemetry(self, t_us: int, message: str, fields: dict[str, Any]) -> None:
        """Append one autopilot message received at ``t_us`` (the frames' clock) to
        ``telemetry.csv`` (format version 2): its MAVLink fields as one JSON object."""
        self._open("telemetry.csv", TELEMETRY_HEADER).writerow(
            [t_us, message, json.dumps(fields, separators=(",", ":"))])

    def close(self) -> None:
        """Flush and close every CSV (idempotent)."""
        for fh, _ in self._files.values():
            fh.close()
        self._files.clear()
        if self._video is not None:
            self._video.release()
            self._video = None

    def __enter__(self) -> StreamWriter:
        return self

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def _rows(path: Path, header: tuple[str, ...]) -> tuple[list[str], list[list[str]]]:
    fh, names, reader = open_csv(path, header)
    with fh:
        return names, [r for r in reader if r]


def read_truth_boxes(folder: Path) -> dict[int, list[TruthBox]]:
    """``truth_boxes.csv`` as {frame index: boxes}; empty when the file is absent."""
    path = Path(folder) / "truth_boxes.csv"
    if not path.exists():
        return {}
    names, rows = _rows(path, BOXES_HEADER)
    out: dict[int, list[TruthBox]] = {}
    for n, row in enumerate(rows, start=2):
        try:
            index, box = parse_box_row([c.strip() for c in row], names)
        except (ValueError, IndexError):
            raise InputError(f"{path}:{n}: malformed row {row}") from None
        out.setdefault(index, []).append(box)
    return out


def read_truth_pose(folder: Path) -> dict[int, tuple[int, TruthPose]]:
    """``truth_pose.csv`` as {frame index: (t_us, pose)}; empty when absent."""
    path = Path(folder) / "truth_pose.csv"
    if not path.exists():
        return {}
    _, rows = _rows(path, POSE_HEADER)
    out: dict[int, tuple[int, TruthPose]] = {}
    for n, row in enumerate(rows, start=2):
        try:
            index, t_us, pose = parse_pose_row(row)
        except (ValueError, IndexError):
            raise InputError(f"{path}:{n}: malformed row {row}") from None
        out[index] = (t_us, pose)
    return out


def read_truth_camera(folder: Path) -> dict[int, TruthCamera]:
    """``truth_camera.csv`` as {frame index: camera pose}; empty when absent."""
    path = Path(folder) / "truth_camera.csv"
    if not path.exists():
        return {}
    _, rows = _rows(path, CAMERA_HEADER)
    out: dict[int, TruthCamera] = {}
    for n, row in enumerate(rows, start=2):
        try:
            index, cam = parse_camera_row(row)
        except (ValueError, IndexError):
            raise InputError(f"{path}:{n}: malformed row {row}") from None
        out[index] = cam
    return out


def read_truth_range(folder: Path) -> dict[int, float | None]:
    """``truth_range.csv`` as {frame index: range in m, None for a dropout}."""
    path = Path(folder) / "truth_range.csv"
    if not path.exists():
        return {}
    _, rows = _rows(path, RANGE_HEADER)
    out: dict[int, float | None] = {}
    for n, row in enumerate(rows, start=2):
        try:
            out[int(row[0])] = float(row[2]) if row[2].strip() else None
        except (ValueError, IndexError):
            raise InputError(f"{path}:{n}: malformed row {row}") from None
    return out


def read_truth(folder: Path) -> dict[int, FrameTruth]:
    """All truth files of a stream as {frame index: FrameTruth} (empty without truth)."""
    folder = Path(folder)
    boxes, poses = read_truth_boxes(folder), read_truth_pose(folder)
    cameras, ranges = read_truth_camera(folder), read_truth_range(folder)
    out: dict[int, FrameTruth] = {}
    for index in sorted(set(boxes) | set(poses) | set(cameras) | set(ranges)):
        pose = poses.get(index)
        out[index] = FrameTruth(tuple(boxes.get(index, ())), pose[1] if pose else None,
                                cameras.get(index), ranges.get(index))
    return out


def read_telemetry(folder: Path) -> list[tuple[int, str, dict[str, Any]]]:
    """``telemetry.csv`` (format version 2) as (t_us, message name, fields) in file order;
    empty when absent (a version-1 stream, or one recorded without an autopilot)."""
    path = Path(folder) / "telemetry.csv"
    if not path.exists():
        return []
    _, rows = _rows(path, TELEMETRY_HEADER)
    out: list[tuple[int, str, dict[str, Any]]] = []
    for n, row in enumerate(rows, start=2):
        try:
            fields = json.loads(row[2])
            if not isinstance(fields, dict):
                raise ValueError(row[2])
            out.append((int(row[0]), row[1].strip(), fields))
        except (ValueError, IndexError):
            raise InputError(f"{path}:{n}: malformed row {row}") from None
    return out
