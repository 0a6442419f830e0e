"""Pure tracking metrics (OTB conventions).

- centre error: Euclidean distance (px) between box centres; NaN when the tracker gave no box;
- precision at 20 px: fraction of visible frames whose centre error is <= 20 px (no box = miss);
- success AUC: mean over IoU thresholds 0, 0.05, ..., 1 of the fraction of visible frames whose
  IoU exceeds the threshold (no box = IoU 0), i.e. the area under the success plot;
- frames lost: visible frames (truth present) where the tracker reported no box.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
SUCCESS_THRESHOLDS = np.linspace(0.0, 1.0, 21)
PRECISION_THRESHOLDS_PX = np.arange(0.0, 51.0)


def boxes_array(boxes: Sequence[Sequence[float] | None]) -> FloatArray:
    """(N, 4) array of (x, y, w, h); rows of NaN where a box is None."""
    out = np.full((len(boxes), 4), np.nan)
    for i, b in enumerate(boxes):
        if b is not None:
            out[i] = b
    return out


def visible(truth: FloatArray) -> npt.NDArray[np.bool_]:
    """Frames whose truth box exists (finite, positive size)."""
    ok = np.isfinite(truth).all(axis=1)
    return ok & (np.nan_to_num(truth[:, 2]) > 0) & (np.nan_to_num(truth[:, 3]) > 0)


def centre_errors(pred: FloatArray, truth: FloatArray) -> FloatArray:
    """Per-frame centre distance in px (NaN where either box is missing)."""
    pc = pred[:, :2] + pred[:, 2:] / 2.0
    tc = truth[:, :2] + truth[:, 2:] / 2.0
    return np.linalg.norm(pc - tc, axis=1)


def centre_errors_xy(pred: FloatArray, truth: FloatArray) -> FloatArray:
    """Per-frame absolute centre error in x and in y, shape (N, 2)."""
    return np.abs((pred[:, :2] + pred[:, 2:] / 2.0) - (truth[:, :2] + truth[:, 2:] / 2.0))


def ious(pred: FloatArray, truth: FloatArray) -> FloatArray:
    """Per-frame intersection over union; 0 where the prediction is missing."""
    x0 = np.maximum(pred[:, 0], truth[:, 0])
    y0 = np.maximum(pred[:, 1], truth[:, 1])
    x1 = np.minimum(pred[:, 0] + pred[:, 2], truth[:, 0] + truth[:, 2])
    y1 = np.minimum(pred[:, 1] + pred[:, 3], truth[:, 1] + truth[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = pred[:, 2] * pred[:, 3] + truth[:, 2] * truth[:, 3] - inter
    out = inter / np.where(union > 0, union, 1.0)
    return np.nan_to_num(out, nan=0.0)


def success_curve(iou: FloatArray) -> FloatArray:
    """Fraction of frames with IoU > t for each t in SUCCESS_THRESHOLDS."""
    if iou.size == 0:
        return np.zeros_like(SUCCESS_THRESHOLDS)
    return (iou[None, :] > SUCCESS_THRESHOLDS[:, None]).mean(axis=1)


def precision_curve(err: FloatArray) -> FloatArray:
    """Fraction of frames with centre error <= t for t in PRECISION_THRESHOLDS_PX (NaN = miss)."""
    if err.size == 0:
        return np.zeros_like(PRECISION_THRESHOLDS_PX)
    e = np.nan_to_num(err, nan=np.inf)
    return (e[None, :] <= PRECISION_THRESHOLDS_PX[:, None]).mean(axis=1)


@dataclass(frozen=True)
class Scores:
    """Accuracy of one tracker on one sequence (frame 0, the init frame, excluded)."""

    frames: int
    mean_centre_error_px: float
    median_centre_error_px: float
    mean_error_x_px: float
    mean_error_y_px: float
    precision_20px: float
    success_auc: float
    frames_lost: int


def score(pred_boxes: Sequence[Sequence[float] | None], truth: FloatArray) -> Scores:
    """Score predicted boxes against truth boxes (same length, frame-aligned)."""
    pred = boxes_array(pred_boxes)
    if pred.shape != truth.shape:
        raise ValueError(f"pred_boxes: expected {truth.shape[0]} boxes, got {pred.shape[0]}")
    vis = visible(truth)
    p, t = pred[vis], truth[vis]
    err = centre_errors(p, t)
    exy = centre_errors_xy(p, t)
    tracked = np.isfinite(err)
    iou = ious(p, t)

    def stat(values: FloatArray, fn: str) -> float:
        return float(getattr(np, fn)(values)) if values.size else float("nan")

    return Scores(
        frames=int(vis.sum()),
        mean_centre_error_px=stat(err[tracked], "mean"),
        median_centre_error_px=stat(err[tracked], "median"),
        mean_error_x_px=stat(exy[tracked, 0], "mean"),
        mean_error_y_px=stat(exy[tracked, 1], "mean"),
        precision_20px=float(precision_curve(err)[20]) if err.size else 0.0,
        success_auc=float(success_curve(iou).mean()),
        frames_lost=int((~tracked).sum()),
    )
