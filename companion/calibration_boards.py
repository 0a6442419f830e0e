"""Calibration boards seen by the simulated camera (``companion calibrate``'s tests and CI).

A chessboard or ChArUco board (:class:`companion.calibration.BoardSpec`) is a textured quad
of the simulated world, drawn by :class:`companion.sim.render.Renderer` with the camera's
known intrinsics and distortion, so a calibration's result can be compared with the truth.

A real sensor integrates the light over each pixel's area; the renderer samples the
texture at each pixel's centre (a bilinear warp), which aliases the board's edges when the
texture is minified and moves them by a fraction of a pixel.  The board camera therefore
renders at ``supersample`` times the resolution (the same lens: focal lengths and principal
point scaled, the distortion coefficients unchanged) and averages each block of
``supersample`` x ``supersample`` pixels (``cv2.INTER_AREA``): the image a camera with a
100 % fill factor would record.  ChArUco corners, which sit next to the markers' edges,
moved by up to 0.6 px without it (docs/decisions.md).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.calibration import BoardSpec, board_texture
from companion.sim.render import Renderer
from companion.sim.trajectory import KinematicState
from companion.sim.world import Quad, World
from companion.sources.base import ImageU8
from tracker.camera import CameraModel
from tracker.geometry import FloatArray

#: camera frame (x right, y down, z forward) -> NED of a level camera looking north
CAM_TO_NED = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
LEVEL = KinematicState(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class BoardView:
    """Where the board's centre appears (pixels), how far it is and how it is turned."""

    centre_px: tuple[float, float]
    distance_m: float
    tilt_deg: tuple[float, float, float]  # about the board's x, y, z axes


def _rotation(tilt_deg: tuple[float, float, float]) -> FloatArray:
    ax, ay, az = np.radians(tilt_deg)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return np.asarray(rz @ ry @ rx, dtype=np.float64)


def board_quad(spec: BoardSpec, texture: ImageU8, camera: CameraModel, view: BoardView) -> Quad:
    """The board as a world quad placed so that the level camera sees it as ``view`` says."""
    width_m, height_m = spec.outer_size_m
    ray = np.linalg.solve(camera.matrix, np.array([*view.centre_px, 1.0]))
    centre = ray / np.linalg.norm(ray) * view.distance_m
    half = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
    half *= (width_m / 2.0, height_m / 2.0, 1.0)
    corners_cam = centre + half @ _rotation(view.tilt_deg).T  # TL, TR, BR, BL
    return Quad(corners_cam @ CAM_TO_NED.T, texture, two_sided=True, landmark_id="board")


def scaled(camera: CameraModel, factor: int) -> CameraModel:
    """The same lens on a sensor with ``factor`` x ``factor`` pixels in place of each pixel.

    With OpenCV's convention (pixel centres at integers) fine pixel ``U`` covers coarse
    pixel ``u`` where ``U = factor * u + (factor - 1) / 2``."""
    shift = (factor - 1) / 2.0
    return CameraModel(camera.width * factor, camera.height * factor, camera.fx * factor,
                       camera.fy * factor, camera.cx * factor + shift,
                       camera.cy * factor + shift, camera.distortion, (0.0, 0.0, 0.0))


class BoardCamera:
    """Renders a board (or no board) through a camera model, with the scenery behind it,
    each pixel the mean of ``supersample`` x ``supersample`` samples over its area."""

    def __init__(self, camera: CameraModel, spec: BoardSpec, px_per_square: int = 40,
                 supersample: int = 4) -> None:
        self.camera = scaled(camera, 1)  # level mount: the board is placed in camera axes
        self.spec = spec
        self.supersample = supersample
        self.texture = board_texture(spec, px_per_square)
        self.renderer = Renderer(scaled(camera, supersample), World([]))

    def render(self, view: BoardView | None, blur_sigma_px: float = 0.0) -> ImageU8:
        """One frame showing the board as ``view`` says (None: no board)."""
        extra = [] if view is None else [board_quad(self.spec, self.texture, self.camera, view)]
        image = self.renderer.render(LEVEL, extra).image
        if self.supersample > 1:
            size = (self.camera.width, self.camera.height)
            image = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA),
                               dtype=np.uint8)
        if blur_sigma_px > 0:
            image = np.asarray(cv2.GaussianBlur(image, (0, 0), blur_sigma_px), dtype=np.uint8)
        return image


    def true_corners(self, view: BoardView) -> FloatArray:
        """Where the board's inner corners are in the image (N x 2, OpenCV's chessboard
        corner order: row by row from the board's top left; ChArUco corner ids)."""
        pc = board_quad(self.spec, self.texture, self.camera, view).corners_ned @ CAM_TO_NED
        cols, rows = self.spec.squares
        across, down = (pc[1] - pc[0]) / (cols + 2), (pc[3] - pc[0]) / (rows + 2)
        points = [pc[0] + (i + 2) * across + (j + 2) * down
                  for j in range(rows - 1) for i in range(cols - 1)]
        return self.camera.project_camera_points(np.asarray(points))


def spread_views(camera: CameraModel, count: int, seed: int = 0, reach: float = 0.75,
                 distance_m: tuple[float, float] = (0.45, 0.75)) -> Iterator[BoardView]:
    """Views whose centres spread over the central ``reach`` of the image, tilted up to
    35 degrees: what a careful calibration session looks like."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        gx, gy = (k % side + 0.5) / side, (k // side % side + 0.5) / side
        u = camera.width * (0.5 + reach * (gx - 0.5)) + rng.uniform(-10, 10)
        v = camera.height * (0.5 + reach * (gy - 0.5)) + rng.uniform(-10, 10)
        tilt = (float(rng.uniform(-35, 35)), float(rng.uniform(-35, 35)),
                float(rng.uniform(-15, 15)))
        yield BoardView((u, v), float(rng.uniform(*distance_m)), tilt)


def write_views(folder: Path, images: list[ImageU8]) -> list[Path]:
    """PNG files ``view_00.png``... in ``folder`` (created)."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, image in enumerate(images):
        path = folder / f"view_{i:02d}.png"
        cv2.imwrite(str(path), image)
        paths.append(path)
    return paths

