"""The monitoring preview: a downscaled frame with tracks drawn on it, as JPEG."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

GREEN, YELLOW, WHITE, CYAN = (80, 220, 80), (0, 220, 255), (255, 255, 255), (255, 220, 0)


def render_preview(image: npt.NDArray[np.uint8], tracks: Sequence[dict[str, Any]],
                   width_px: int, quality: int, caption: str = "") -> bytes:
    """JPEG bytes of ``image`` scaled to ``width_px`` wide with each track's box (green),
    corners (yellow), particles (cyan dots), landmark id and confidence."""
    h, w = image.shape[:2]
    scale = min(1.0, width_px / w)
    out = cv2.resize(image, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
    for t in tracks:
        x, y, bw, bh = (float(v) * scale for v in t["box"])
        cv2.rectangle(out, (round(x), round(y)), (round(x + bw), round(y + bh)), GREEN, 1)
        if t.get("corners"):
            quad = np.round(np.asarray(t["corners"], np.float64) * scale).astype(np.int32)
            cv2.polylines(out, [quad.reshape(-1, 1, 2)], True, YELLOW, 1)
        for px, py in np.asarray(t.get("particles", ()), np.float64).reshape(-1, 2):
            cv2.circle(out, (round(px * scale), round(py * scale)), 1, CYAN, -1)
        label = f"{t['landmark_id']} {float(t.get('confidence', 0.0)):.2f}"
        cv2.putText(out, label, (round(x), max(10, round(y) - 3)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.35, WHITE, 1, cv2.LINE_AA)
    if caption:
        cv2.putText(out, caption, (4, out.shape[0] - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.35, WHITE,
                    1, cv2.LINE_AA)
    ok, jpeg = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("image: cannot encode the preview as JPEG")
    return bytes(jpeg.tobytes())
