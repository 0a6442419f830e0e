"""Frames for ``companion calibrate``: a folder of images, a video file or a live camera,
and the camera file written atomically (only after a calibration was accepted)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from companion.calibration import ImageU8
from companion.errors import InputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def folder_frames(folder: Path) -> Iterator[tuple[str, ImageU8]]:
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


def capture_frames(spec: str, every_s: float, seconds: float | None,
                   live: bool) -> Iterator[tuple[str, ImageU8]]:
    """Frames of a video file or a live camera (a device index, a V4L2 path, a GStreamer
    pipeline or a URL), one every ``every_s`` seconds, for at most ``seconds``."""
    target: int | str = int(spec) if live and spec.isdigit() else spec
    if not live and not Path(spec).is_file():
        raise InputError(f"calibrate: {spec}: no such video file")
    cap = cv2.VideoCapture(target)
    if not cap.isOpened():
        raise InputError(f"calibrate: cannot open {'camera' if live else 'video'} {spec}")
    start, next_t, index = time.monotonic(), 0.0, 0
    try:
        while seconds is None or time.monotonic() - start < seconds:
            ok, image = cap.read()
            if not ok:
                if live:
                    raise InputError(f"calibrate: camera {spec} stopped delivering frames")
                return
            t = time.monotonic() - start if live else cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
            index += 1
            if t + 1e-9 >= next_t:
                next_t = t + every_s
                yield f"frame {index} ({t:.1f} s)", np.asarray(image, dtype=np.uint8)
    finally:
        cap.release()


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
