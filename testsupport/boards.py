"""Rendered calibration sessions: boards seen by the simulated camera with known intrinsics
and distortion (shared by the calibrate tests and the installed-wheel test)."""

from __future__ import annotations

from pathlib import Path

from companion.calibration import BoardSpec
from companion.calibration_boards import BoardCamera, BoardView, spread_views, write_views
from tracker.camera import CameraModel

#: A 640x480 camera with the barrel distortion of config/scenarios/survey_distorted.toml and
#: a principal point off the centre (the fit must find it, not assume it).
TRUTH = CameraModel(640, 480, 525.0, 522.0, 322.5, 236.0, (-0.28, 0.09, 0.0005, -0.0005, 0.0))
CHESSBOARD = BoardSpec()
CHARUCO = BoardSpec("charuco", (7, 5), 0.05, 0.035)
#: Texture pixels per square: a chessboard drawn small is magnified (sharp, exact edges);
#: ChArUco markers need more pixels to be decoded.
PX_PER_SQUARE = {"chessboard": 16, "charuco": 64}
#: Board centres at the corners and edges of the frame, half the board outside.
EDGES = [(20, 30), (620, 40), (600, 460), (30, 450), (320, 10), (320, 475), (5, 240), (635, 240)]


def session(folder: Path, kind: str = "chessboard", count: int = 25, seed: int = 1,
            blur_sigma_px: float = 0.0, board: bool = True, reach: float = 0.75,
            distance_m: tuple[float, float] = (0.45, 0.75)) -> Path:
    """``count`` rendered views of a board in ``folder`` (PNG files)."""
    spec = CHESSBOARD if kind == "chessboard" else CHARUCO
    cam = BoardCamera(TRUTH, spec, PX_PER_SQUARE[kind])
    views = spread_views(TRUTH, count, seed, reach, distance_m)
    write_views(folder, [cam.render(v if board else None, blur_sigma_px) for v in views])
    return folder


def partial_session(folder: Path) -> Path:
    """Views of a chessboard whose centre is at the frame's edges: part of it is outside."""
    cam = BoardCamera(TRUTH, CHESSBOARD, PX_PER_SQUARE["chessboard"])
    write_views(folder, [cam.render(BoardView(c, 0.5, (10.0, -10.0, 5.0))) for c in EDGES * 2])
    return folder
