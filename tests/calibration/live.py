"""A stand-in for a live camera (``companion calibrate camera --camera``): frames come in
real time at the camera's rate, whatever the reader does, and show what a person holding a
board shows -- the board still at one pose for a while, then blurred while it is moved to
the next -- over and over until the session stops.

It has the four methods of ``cv2.VideoCapture`` that the capture code uses and is put in
place of ``companion.calibration_io.open_capture``; everything after it (pacing, the time
limit, picking views, progress, the refusals) is the code a real camera goes through."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from companion.calibration import ImageU8
from companion.calibration_boards import BoardCamera, spread_views
from testsupport.boards import CHESSBOARD, PX_PER_SQUARE, TRUTH


@dataclass
class LiveBoardCamera:
    """``poses`` (sharp frames) each held ``hold_s``, with ``move_s`` of a blurred frame
    between them, looping; ``fps`` frames a second in real time; read() fails after
    ``fail_after`` frames (a camera unplugged) when set."""

    poses: list[ImageU8]
    moving: list[ImageU8]
    fps: float = 30.0
    hold_s: float = 0.3
    move_s: float = 0.1
    fail_after: int | None = None
    opened: bool = True
    targets: list[int | str] = field(default_factory=list)
    delivered: int = 0
    released: bool = False
    _start: float = 0.0

    def open(self, target: int | str) -> LiveBoardCamera:
        """What ``open_capture`` returns for ``target``."""
        self.targets.append(target)
        self._start = time.monotonic()
        return self

    def isOpened(self) -> bool:  # noqa: N802 (OpenCV's name)
        return self.opened

    def read(self) -> tuple[bool, np.ndarray | None]:
        """The next frame, when it is due (a camera that is read late skips frames)."""
        if self.fail_after is not None and self.delivered >= self.fail_after:
            return False, None
        due = self._start + self.delivered / self.fps
        now = time.monotonic()
        if now < due:
            time.sleep(due - now)
        else:
            self.delivered = int((now - self._start) * self.fps)  # frames dropped
        t = self.delivered / self.fps
        self.delivered += 1
        cycle = self.hold_s + self.move_s
        k, phase = divmod(t, cycle)
        pose = int(k) % len(self.poses)
        image = self.poses[pose] if phase < self.hold_s else self.moving[pose]
        return True, image.copy()

    def get(self, prop_id: int) -> float:
        return self.fps if prop_id == cv2.CAP_PROP_FPS else 0.0

    def release(self) -> None:
        self.released = True


def live_camera(count: int, seed: int = 3, fail_after: int | None = None) -> LiveBoardCamera:
    """A camera showing a chessboard at ``count`` poses spread over the image."""
    cam = BoardCamera(TRUTH, CHESSBOARD, PX_PER_SQUARE["chessboard"])
    views = list(spread_views(TRUTH, count, seed))
    poses = [cam.render(v) for v in views]
    moving = [np.asarray(cv2.GaussianBlur(p, (0, 0), 2.0), np.uint8) for p in poses]
    return LiveBoardCamera(poses, moving, fail_after=fail_after)
