"""Frames for ``companion calibrate``: a folder of images, a video file or a live camera,
and the camera file written atomically (only after a calibration was accepted)."""

from __future__ import annotations

import os
import time
from collections.abc import Generator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from companion.calibration import ImageU8
from companion.errors import InputError

Frames = Generator[tuple[str, ImageU8], None, None]
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def folder_frames(folder: Path) -> Frames:
    """Every image in ``folder``, by name."""
    if not folder.is_dir():
        raise InputError(f"calibrate: {folder}: no such folder")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise InputError(f"calibrate: {folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f"calibrate: {path}: not a readable image")
        yield path.name, np.asarray(image, dtype=np.uint8)


class Capture(Protocol):
    """What is used of ``cv2.VideoCapture`` (a test's stand-in for a camera has these)."""

    def isOpened(self) -> bool: ...  # noqa: N802 (OpenCV's name)

    def read(self) -> tuple[bool, np.ndarray | None]: ...

    def get(self, prop_id: int) -> float: ...

    def release(self) -> None: ...


def open_capture(target: int | str) -> Capture:
    """The camera or video file behind ``target`` (OpenCV's VideoCapture)."""
    return cv2.VideoCapture(target)


@dataclass
class CaptureSession:
    """Frames of a video file or a live camera (a device index, a V4L2 path, a GStreamer
    pipeline or a URL), one every ``every_s`` seconds; a camera for at most ``seconds``.

    A camera is read continuously (frames in between are dropped, so what is looked at is
    what the camera sees now); ``timed_out`` says that the session ended at the limit."""

    spec: str
    every_s: float
    seconds: float | None = None
    live: bool = False
    timed_out: bool = False

    def frames(self) -> Frames:
        """(name, image) pairs; the name says the frame's number and time."""
        live, spec = self.live, self.spec
        if not live and not Path(spec).is_file():
            raise InputError(f"calibrate: {spec}: no such video file")
        cap = open_capture(int(spec) if live and spec.isdigit() else spec)
        if not cap.isOpened():
            raise InputError(f"calibrate: cannot open {'camera' if live else 'video'} {spec}")
        limit = "" if self.seconds is None else f" of {self.seconds:g}"
        start, next_t, index = time.monotonic(), 0.0, 0
        try:
            while not (live and self._past_limit(start)):
                ok, image = cap.read()
                if not ok or image is None:
                    if live:
                        raise InputError(f"calibrate: camera {spec} stopped delivering frames")
                    return
                t = time.monotonic() - start if live else cap.get(cv2.CAP_PROP_POS_MSEC) / 1e3
                index += 1
                if t + 1e-9 >= next_t:
                    next_t = t + self.every_s
                    yield f"frame {index} ({t:.1f}{limit} s)", np.asarray(image, dtype=np.uint8)
        finally:
            cap.release()

    def _past_limit(self, start: float) -> bool:
        self.timed_out = self.seconds is not None and time.monotonic() - start >= self.seconds
        return self.timed_out


def refuse_existing(path: Path, overwrite: bool) -> None:
    """One line when ``path`` exists and may not be replaced (checked before a session
    and again when writing)."""
    if path.exists() and not overwrite:
        raise InputError(f"{path}: exists (use --overwrite to replace it)")


def write_atomically(path: Path, text: str, overwrite: bool) -> None:
    """Write ``text`` to ``path`` through a temporary file; refuse to replace a file
    unless ``overwrite``."""
    refuse_existing(path, overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
