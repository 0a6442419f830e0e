"""Loading evaluation sequences: OTB layout and recorded frame streams with truth boxes."""

from __future__ import annotations

import csv
import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import InputError

_IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}


@dataclass(frozen=True)
class Sequence:
    """A sequence of frame files with one truth box (x, y, w, h; 0-based px) per frame."""

    name: str
    frames: tuple[Path, ...]
    truth: npt.NDArray[np.float64]  # (N, 4); NaN rows where the target is absent

    def images(self) -> Iterator[npt.NDArray[np.uint8]]:
        """Decode the frames one by one as BGR uint8."""
        for path in self.frames:
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                raise InputError(f"{path}: cannot decode image")
            yield image


def _numbers(line: str) -> list[float]:
    return [float(v) for v in re.split(r"[,\s]+", line.strip()) if v]


def load_otb(folder: Path) -> Sequence:
    """OTB layout: ``img/*.jpg`` and ``groundtruth_rect.txt`` (1-based x, y, w, h per line)."""
    gt = folder / "groundtruth_rect.txt"
    frames = sorted(p for p in (folder / "img").iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    rows = []
    for number, line in enumerate(gt.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            values = _numbers(line)
        except ValueError as err:
            raise InputError(f"{gt}:{number}: expected x,y,w,h numbers, got {line!r}") from err
        if len(values) != 4:
            raise InputError(f"{gt}:{number}: expected 4 numbers x,y,w,h, got {len(values)}")
        rows.append(values)
    truth = np.array(rows, dtype=np.float64)
    truth[:, :2] -= 1.0  # OTB is 1-based
    absent = ~np.isfinite(truth).all(axis=1) | (truth[:, 2] <= 0) | (truth[:, 3] <= 0)
    truth[absent] = np.nan
    n = min(len(frames), len(truth))
    if n < 2:
        raise InputError(f"{folder}: expected at least 2 frames with truth, got {n}")
    return Sequence(folder.name, tuple(frames[:n]), truth[:n])


def load_stream(folder: Path, landmark_id: str | None = None) -> Sequence:
    """Recorded stream: ``stream.toml``, ``frames.csv`` (index, t_us, file), ``truth_boxes.csv``.

    Only image-file streams are read; the first landmark id in ``truth_boxes.csv`` is used
    unless ``landmark_id`` is given.
    """
    meta = tomllib.loads((folder / "stream.toml").read_text())
    if meta.get("format") != "landmark-companion-stream":
        raise InputError(f"{folder / 'stream.toml'}: not a landmark-companion-stream")
    if int(meta.get("version", 1)) > 1:
        raise InputError(f"{folder / 'stream.toml'}: version {meta['version']} is newer than 1")
    with (folder / "frames.csv").open(newline="") as fh:
        frames = {int(r["index"]): folder / r["file"] for r in csv.DictReader(fh)}
    truth_rows: dict[int, list[float]] = {}
    with (folder / "truth_boxes.csv").open(newline="") as fh:
        for r in csv.DictReader(fh):
            landmark_id = landmark_id or r["landmark_id"]
            if r["landmark_id"] == landmark_id:
                truth_rows[int(r["index"])] = [float(r[k]) for k in ("x", "y", "w", "h")]
    indices = sorted(frames)
    truth = np.array([truth_rows.get(i, [np.nan] * 4) for i in indices], dtype=np.float64)
    return Sequence(folder.name, tuple(frames[i] for i in indices), truth)


def load_sequence(folder: Path) -> Sequence:
    """Load a folder in either layout (recorded stream if it has ``stream.toml``)."""
    if (folder / "stream.toml").is_file():
        return load_stream(folder)
    if (folder / "groundtruth_rect.txt").is_file() and (folder / "img").is_dir():
        return load_otb(folder)
    raise InputError(
        f"{folder}: expected an OTB folder (img/, groundtruth_rect.txt) or a recorded stream "
        "(stream.toml, frames.csv, truth_boxes.csv)"
    )
