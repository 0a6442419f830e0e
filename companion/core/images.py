"""Reading and writing single image files, with truncation and corruption checks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from companion.core.frames import ImageU8

_PNG_END = b"IEND\xaeB`\x82"
_JPEG_END = b"\xff\xd9"


class ImageProblem(Exception):  # noqa: N818  (carries a skip reason, caught by the sources)
    """An image file that cannot be used; ``reason`` is a short counter key."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def looks_truncated(data: bytes, suffix: str) -> bool:
    """True when a PNG lacks its IEND chunk or a JPEG lacks its end-of-image marker."""
    suffix = suffix.lower()
    tail = data[-64:].rstrip(b"\x00\r\n ")
    if suffix == ".png":
        return not tail.endswith(_PNG_END)
    if suffix in (".jpg", ".jpeg"):
        return _JPEG_END not in tail
    return False


def read_image(path: Path) -> ImageU8:
    """Read one image file as HxWx3 BGR uint8 or raise :class:`ImageProblem`."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ImageProblem("missing", f"{path}: image file is missing") from None
    except OSError as err:
        raise ImageProblem("unreadable", f"{path}: cannot read ({err.strerror})") from err
    if not data:
        raise ImageProblem("truncated", f"{path}: image file is empty")
    if looks_truncated(data, path.suffix):
        raise ImageProblem("truncated", f"{path}: image file is truncated")
    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ImageProblem("corrupt", f"{path}: not a readable image")
    return np.ascontiguousarray(image, dtype=np.uint8)


def write_image(path: Path, image: ImageU8, jpeg_quality: int = 95) -> None:
    """Write one BGR uint8 image; PNG is lossless, JPEG uses ``jpeg_quality``."""
    params: list[int] = []
    if path.suffix.lower() in (".jpg", ".jpeg"):
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
    elif path.suffix.lower() == ".png":
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, buf = cv2.imencode(path.suffix, image, params)
    if not ok:
        raise OSError(f"{path}: OpenCV could not encode the image")
    path.write_bytes(buf.tobytes())
