"""Argument checks shared by the trackers: bad input raises ``ValueError`` naming the argument."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from tracker.types import Box


def check_image(image: Any, name: str = "image_bgr") -> npt.NDArray[np.uint8]:
    """Return ``image`` if it is an HxWx3 uint8 array (BGR), else raise ``ValueError``."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name}: expected a numpy array HxWx3 uint8 (BGR), got {type(image)!r}")
    if image.dtype != np.uint8:
        raise ValueError(f"{name}: expected dtype uint8, got {image.dtype}")
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{name}: expected shape HxWx3 (3 channels, BGR), got {image.shape}")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f"{name}: expected an image of at least 2x2 pixels, got {image.shape}")
    return image


def check_box(box: Any, image_shape: tuple[int, ...], name: str = "box") -> Box:
    """Return ``box`` as floats if it is a finite (x, y, w, h) with w, h > 0 inside the image."""
    try:
        values = tuple(float(v) for v in box)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name}: expected four numbers (x, y, w, h), got {box!r}") from err
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name}: expected four finite numbers (x, y, w, h), got {box!r}")
    x, y, w, h = values
    if w < 1.0 or h < 1.0:
        raise ValueError(f"{name}: expected width and height >= 1 px, got w={w:g}, h={h:g}")
    height, width = image_shape[0], image_shape[1]
    if x < 0 or y < 0 or x + w > width or y + h > height:
        raise ValueError(
            f"{name}: expected a box inside the {width}x{height} image, got "
            f"(x={x:g}, y={y:g}, w={w:g}, h={h:g})"
        )
    return (x, y, w, h)


def check_same_frame(image: Any, shape: tuple[int, ...], name: str = "image_bgr") -> None:
    """Check a later frame: same HxWx3 uint8 layout as the first one."""
    check_image(image, name)
    if image.shape != shape:
        raise ValueError(
            f"{name}: expected a frame of the same size as the first one {shape}, got {image.shape}"
        )
