"""Evaluation sequences: OTB folders and recorded streams with truth boxes.

Reading the files is left to :mod:`companion.sources` (one parser per format); this module only
pairs frames with one target's truth box per frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from companion.core.images import ImageProblem, read_image
from companion.core.stream_format import read_meta
from companion.core.stream_io import read_truth_boxes
from companion.errors import InputError
from companion.sources.files import IMAGE_SUFFIXES, read_frame_list, read_otb_groundtruth


@dataclass(frozen=True)
class Sequence:
    """Frame files with one truth box (x, y, w, h; 0-based px) per frame; NaN rows = absent."""

    name: str
    frames: tuple[Path, ...]
    truth: npt.NDArray[np.float64]

    def images(self) -> Iterator[npt.NDArray[np.uint8]]:
        """Decode the frames one by one as BGR uint8."""
        for path in self.frames:
            try:
                yield read_image(path)
            except ImageProblem as err:
                raise InputError(f"{path}: {err}") from err


def _mark_absent(truth: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    out = truth.astype(np.float64).copy()
    absent = ~np.isfinite(out).all(axis=1) | (out[:, 2] <= 0) | (out[:, 3] <= 0)
    out[absent] = np.nan
    return out


def load_otb(folder: Path) -> Sequence:
    """OTB layout: ``img/*.jpg`` and ``groundtruth_rect.txt`` (1-based x, y, w, h per line)."""
    img = folder / "img"
    if not img.is_dir():
        raise InputError(f"{folder}: not an OTB sequence folder (no img/)")
    frames = sorted(p for p in img.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    truth = _mark_absent(read_otb_groundtruth(folder))
    n = min(len(frames), len(truth))
    if n < 2:
        raise InputError(f"{folder}: expected at least 2 frames with truth, got {n}")
    return Sequence(folder.name, tuple(frames[:n]), truth[:n])


def load_stream(folder: Path, landmark_id: str | None = None) -> Sequence:
    """Recorded stream with ``truth_boxes.csv``; the first landmark id unless one is given."""
    read_meta(folder)  # refuses unknown formats and newer versions with a clear message
    _, entries = read_frame_list(folder)
    boxes = read_truth_boxes(folder)
    if not boxes:
        raise InputError(f"{folder}: has no truth_boxes.csv to evaluate against")
    if landmark_id is None:
        landmark_id = next(b.landmark_id for i in sorted(boxes) for b in boxes[i])
    if not any(b.landmark_id == landmark_id for bs in boxes.values() for b in bs):
        raise InputError(f"{folder}: truth_boxes.csv has no landmark {landmark_id!r}")
    truth = np.full((len(entries), 4), np.nan)
    for row, entry in enumerate(entries):
        for b in boxes.get(entry.index, []):
            if b.landmark_id == landmark_id:
                truth[row] = (b.x, b.y, b.w, b.h)
    return Sequence(
        f"{folder.name}:{landmark_id}", tuple(e.path for e in entries), _mark_absent(truth)
    )


def load_sequence(folder: Path, landmark_id: str | None = None) -> Sequence:
    """Load a folder in either layout (recorded stream if it has ``stream.toml``).

    ``landmark_id`` picks the target of a recorded stream (default: the first in the file).
    """
    if (folder / "stream.toml").is_file():
        return load_stream(folder, landmark_id)
    if (folder / "groundtruth_rect.txt").is_file():
        return load_otb(folder)
    raise InputError(
        f"{folder}: expected an OTB folder (img/, groundtruth_rect.txt) or a recorded stream "
        "(stream.toml, frames.csv, truth_boxes.csv)"
    )
