"""Camera calibration from a chessboard or a ChArUco board (``companion calibrate camera``).

Frames come from a folder of images, a video file or a live camera
(:mod:`companion.calibration_io`); each is searched for the board, views that are blurred
are refused (``cv2.estimateChessboardSharpness``: the 10-90 % edge rise, which OpenCV's
documentation wants under ~3 px), the rest are kept while they add something -- a part of
the image not yet covered, or a position, size or tilt unlike the views already kept --
and ``cv2.calibrateCamera`` fits the intrinsics and distortion.  A calibration that cannot
be trusted is refused with one line: no board found, too few sharp views, or views that
leave much of the image uncovered (distortion there would be extrapolated).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import InputError
from tracker.camera import CameraModel

ImageU8 = npt.NDArray[np.uint8]
F32 = npt.NDArray[np.float32]
GRID = 4  # coverage cells per side


class CalibrationError(InputError):
    """A calibration that cannot be trusted: nothing is written."""


@dataclass(frozen=True)
class BoardSpec:
    """The board: ``squares`` across and down; a ChArUco board's markers are ``marker_m``
    wide, from OpenCV's predefined ``dictionary``."""

    kind: Literal["chessboard", "charuco"] = "chessboard"
    squares: tuple[int, int] = (10, 7)
    square_m: float = 0.03
    marker_m: float = 0.022
    dictionary: str = "DICT_5X5_100"

    @property
    def inner(self) -> tuple[int, int]:
        """Inner corners across and down (OpenCV's chessboard pattern size)."""
        return (self.squares[0] - 1, self.squares[1] - 1)

    @property
    def outer_size_m(self) -> tuple[float, float]:
        """Width and height with the one-square white margin the detectors need."""
        return ((self.squares[0] + 2) * self.square_m, (self.squares[1] + 2) * self.square_m)

    def describe(self) -> str:
        """E.g. "chessboard of 10x7 squares (30 mm)"."""
        return (f"{self.kind} of {self.squares[0]}x{self.squares[1]} squares "
                f"({self.square_m * 1000:g} mm)")

    def charuco(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV ChArUco board of this spec."""
        names = [n for n in dir(cv2.aruco) if n.startswith("DICT_")]
        if self.dictionary not in names:
            raise InputError(f"calibrate: unknown ArUco dictionary {self.dictionary!r} "
                             f"(e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, dictionary)


def board_texture(spec: BoardSpec, px_per_square: int = 40) -> ImageU8:
    """The printable board, with a white margin of one square (BGR)."""
    cols, rows = spec.squares
    size = ((cols + 2) * px_per_square, (rows + 2) * px_per_square)
    if spec.kind == "charuco":
        grey = spec.charuco().generateImage(size, marginSize=px_per_square, borderBits=1)
    else:
        grey = np.full((size[1], size[0]), 255, np.uint8)
        for j in range(rows):
            for i in range(cols):
                if (i + j) % 2 == 0:
                    y, x = (j + 1) * px_per_square, (i + 1) * px_per_square
                    grey[y:y + px_per_square, x:x + px_per_square] = 0
    return np.ascontiguousarray(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), dtype=np.uint8)


@dataclass(frozen=True)
class View:
    """A board found in one frame: its corners and how sharp its edges are."""

    name: str
    image_points: F32  # (N, 1, 2)
    object_points: F32  # (N, 1, 3)
    sharpness_px: float  # 10-90 % edge rise; nan where not measured (ChArUco)


def refine(grey: ImageU8, corners: npt.NDArray[np.floating], half_window: int = 5) -> F32:
    """Corners to a fraction of a pixel: the detectors' own are off by 0.1-0.3 px on
    rendered boards (calibrations 0.5 % off in focal length, measured before this step)."""
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    out = cv2.cornerSubPix(grey, corners.astype(np.float32), (half_window, half_window), (-1, -1),
                           criteria)
    return np.asarray(out, dtype=np.float32)


class BoardDetector:
    """Finds the board in a frame."""

    def __init__(self, spec: BoardSpec) -> None:
        self.spec = spec
        self._charuco = None
        if spec.kind == "charuco":
            self._board = spec.charuco()
            self._charuco = cv2.aruco.CharucoDetector(self._board)
        cols, rows = spec.inner
        grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * spec.square_m
        self._object = np.hstack([grid, np.zeros((len(grid), 1))]).astype(np.float32)

    def find(self, name: str, image: ImageU8) -> View | None:
        """The board's view in ``image``, or None."""
        grey = np.asarray(image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY),
                          dtype=np.uint8)
        if self._charuco is not None:
            return self._find_charuco(name, grey)
        flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY
        found, corners = cv2.findChessboardCornersSB(grey, self.spec.inner, flags=flags)
        if not found:
            return None
        fine = refine(grey, np.asarray(corners, dtype=np.float32))
        sharp = cv2.estimateChessboardSharpness(grey, self.spec.inner, fine)[0]
        return View(name, fine.reshape(-1, 1, 2), self._object.reshape(-1, 1, 3),
                    float(np.ravel(sharp)[0]))

    def _find_charuco(self, name: str, grey: ImageU8) -> View | None:
        assert self._charuco is not None
        corners, ids, markers, _ = self._charuco.detectBoard(grey)
        if ids is None or len(ids) < 6:  # fewer corners constrain a view too little
            return None
        fine, ids = refine_charuco(grey, np.asarray(corners, np.float32), np.asarray(ids),
                                   [np.asarray(m, np.float64).reshape(4, 2) for m in markers])
        if len(ids) < 6:
            return None
        obj, img = self._board.matchImagePoints(fine, ids)  # type: ignore[call-overload]
        return View(name, img.astype(np.float32).reshape(-1, 1, 2),
                    obj.astype(np.float32).reshape(-1, 1, 3), math.nan)


def _chebyshev(point: npt.NDArray[np.floating], quad: npt.NDArray[np.float64]) -> float:
    """Distance from ``point`` to the outline of ``quad`` in the max norm: the half side of
    the largest square window around ``point`` that stays clear of the outline."""
    t = np.linspace(0.0, 1.0, 16, endpoint=False)[:, None]
    outline = np.concatenate([quad[i] + t * (quad[(i + 1) % 4] - quad[i]) for i in range(4)])
    return float(np.abs(outline - point).max(axis=1).min())


def refine_charuco(grey: ImageU8, corners: F32, ids: npt.NDArray[np.integer],
                   markers: list[npt.NDArray[np.float64]], margin_px: float = 2.0
                   ) -> tuple[F32, npt.NDArray[np.int32]]:
    """ChArUco corners to a fraction of a pixel, each with the largest window that holds
    no marker: the markers' edges, a few pixels from every corner, pull ``cornerSubPix``
    off the corner.  OpenCV's own refinement sizes its window by the Euclidean distance to
    the nearest marker corner, which lets a square window reach into the marker (corners
    0.2-0.6 px off on rendered boards); a fixed window does the same on small squares
    (2.6 px).  A corner with under 2 px of room on a side is dropped, not guessed."""
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    out: list[F32] = []
    kept: list[int] = []
    for corner, corner_id in zip(corners.reshape(-1, 2), np.ravel(ids), strict=True):
        room = min((_chebyshev(corner, m) for m in markers), default=0.0) - margin_px
        if room < 2.0:
            continue
        half = min(int(room), 10)
        start = np.asarray(corner, np.float32).reshape(1, 1, 2)
        out.append(np.asarray(cv2.cornerSubPix(grey, start, (half, half), (-1, -1), criteria),
                              np.float32).reshape(2))
        kept.append(int(corner_id))
    return (np.asarray(out, np.float32).reshape(-1, 1, 2),
            np.asarray(kept, np.int32).reshape(-1, 1))


@dataclass
class ViewPicker:
    """Keeps views that add coverage or variety, up to ``max_views``."""

    size: tuple[int, int]
    max_views: int = 40
    max_blur_px: float = 4.0
    kept: list[View] = field(default_factory=list)
    frames: int = 0
    found: int = 0
    blurred: int = 0
    _cells: set[tuple[int, int]] = field(default_factory=set)
    _keys: list[npt.NDArray[np.float64]] = field(default_factory=list)

    def offer(self, view: View | None) -> str:
        """Judge one frame's view; returns what happened ("kept", "no board", ...)."""
        self.frames += 1
        if view is None:
            return "no board"
        self.found += 1
        if view.sharpness_px > self.max_blur_px:
            self.blurred += 1
            return f"blurred ({view.sharpness_px:.1f} px edges)"
        if len(self.kept) >= self.max_views:
            return "enough views"
        cells, key = self._cells_of(view), self._key(view)
        new_cells = cells - self._cells
        if not new_cells and any(np.abs(key - k).max() < 0.06 for k in self._keys):
            return "like a view already kept"
        self.kept.append(view)
        self._cells |= cells
        self._keys.append(key)
        return "kept"

    @property
    def coverage(self) -> float:
        """Share of the image's GRID x GRID cells that hold a corner of a kept view."""
        return len(self._cells) / GRID**2

    def _cells_of(self, view: View) -> set[tuple[int, int]]:
        w, h = self.size
        pts = view.image_points.reshape(-1, 2)
        cx = np.clip((pts[:, 0] / w * GRID).astype(int), 0, GRID - 1)
        cy = np.clip((pts[:, 1] / h * GRID).astype(int), 0, GRID - 1)
        return set(zip(cx.tolist(), cy.tolist(), strict=True))

    def _key(self, view: View) -> npt.NDArray[np.float64]:
        """Position, size and tilt (the board outline's foreshortening) in the image."""
        obj = view.object_points.reshape(-1, 3)[:, :2].astype(np.float64)
        img = view.image_points.reshape(-1, 2).astype(np.float64)
        h, _ = cv2.findHomography(obj, img)
        (x0, y0), (x1, y1) = obj.min(axis=0), obj.max(axis=0)
        outline = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]).reshape(-1, 1, 2)
        q = cv2.perspectiveTransform(outline, h).reshape(4, 2)
        top, right = np.linalg.norm(q[1] - q[0]), np.linalg.norm(q[2] - q[1])
        bottom, left = np.linalg.norm(q[3] - q[2]), np.linalg.norm(q[0] - q[3])
        w, hgt = self.size
        return np.array([q[:, 0].mean() / w, q[:, 1].mean() / hgt,
                         (top + bottom) / 2 / w, (left + right) / 2 / hgt,
                         (top - bottom) / (top + bottom), (left - right) / (left + right)])


@dataclass(frozen=True)
class Calibration:
    """The result: the camera model and how well it fits each view."""

    camera: CameraModel
    rms_px: float
    view_rms_px: tuple[tuple[str, float], ...]  # worst first
    coverage: float
    board: BoardSpec


@dataclass(frozen=True)
class Limits:
    """When a calibration is refused."""

    min_views: int = 10
    min_coverage: float = 0.6
    max_views: int = 40
    max_blur_px: float = 4.0
    fit_k3: bool = False


def collect(frames: Iterable[tuple[str, ImageU8]], spec: BoardSpec, limits: Limits,
            progress: Callable[[str], None] | None = None) -> tuple[ViewPicker, tuple[int, int]]:
    """Search the frames for the board and keep the views worth calibrating on, until
    ``limits.max_views`` are kept or the frames end."""
    detector = BoardDetector(spec)
    picker: ViewPicker | None = None
    size = (0, 0)
    for name, image in frames:
        size = (image.shape[1], image.shape[0])
        if picker is None:
            picker = ViewPicker(size, limits.max_views, limits.max_blur_px)
        elif size != picker.size:
            raise CalibrationError(f"calibrate: {name} is {size[0]}x{size[1]}, the frames "
                                   f"before it {picker.size[0]}x{picker.size[1]}")
        verdict = picker.offer(detector.find(name, image))
        if progress is not None:
            progress(f"{name}: {verdict}; {len(picker.kept)} views kept, "
                     f"coverage {picker.coverage:.0%}")
        if len(picker.kept) >= limits.max_views:
            break  # a camera session ends here, not at its time limit
    if picker is None:
        raise CalibrationError("calibrate: no frames to calibrate on")
    return picker, size


def check_views(picker: ViewPicker, spec: BoardSpec, limits: Limits) -> None:
    """Refuse, with one line, views that cannot give a trustworthy calibration: no board,
    no sharp view, views that leave much of the image uncovered, too few views."""
    if picker.found == 0:
        raise CalibrationError(
            f"calibrate: no {spec.describe()} found in any of {picker.frames} frames "
            "(check --board and --squares, and that the whole board is in view)")
    few = (f"calibrate: only {len(picker.kept)} usable views (need {limits.min_views}): the "
           f"board was found in {picker.found} of {picker.frames} frames")
    if picker.blurred and len(picker.kept) < limits.min_views:
        raise CalibrationError(f"{few}; {picker.blurred} were blurred (edges wider than "
                               f"{limits.max_blur_px:g} px): focus, hold still, add light")
    if picker.coverage < limits.min_coverage:
        raise CalibrationError(
            f"calibrate: the views cover {picker.coverage:.0%} of the image (need "
            f"{limits.min_coverage:.0%}): show the board in the corners and along the edges")
    if len(picker.kept) < limits.min_views:
        raise CalibrationError(f"{few}; show it at more positions, distances and tilts")


def calibrate(picker: ViewPicker, size: tuple[int, int], spec: BoardSpec,
              limits: Limits) -> Calibration:
    """Fit intrinsics and distortion to the kept views (after :func:`check_views`)."""
    check_views(picker, spec, limits)
    views = picker.kept
    flags = 0 if limits.fit_k3 else cv2.CALIB_FIX_K3
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
        [v.object_points for v in views], [v.image_points for v in views], size, None, None,
        flags=flags)
    per_view = []
    for v, r, t in zip(views, rvecs, tvecs, strict=True):
        uv, _ = cv2.projectPoints(v.object_points, r, t, k, dist)
        err = uv.reshape(-1, 2) - v.image_points.reshape(-1, 2)
        per_view.append((v.name, float(np.sqrt((err**2).sum(axis=1).mean()))))
    per_view.sort(key=lambda item: -item[1])
    d = [float(x) for x in dist.ravel()[:5]]
    camera = CameraModel(size[0], size[1], float(k[0, 0]), float(k[1, 1]), float(k[0, 2]),
                         float(k[1, 2]), tuple(d))
    return Calibration(camera, float(rms), tuple(per_view), picker.coverage, spec)


def camera_toml(result: Calibration, when: str) -> str:
    """The camera file in the project's format (``config/cameras/``)."""
    c = result.camera
    dist = ", ".join(f"{v:.6g}" for v in c.distortion)
    return (
        f"# Camera model measured by companion calibrate ({when}): {len(result.view_rms_px)} "
        f"views of a\n# {result.board.describe()}, RMS reprojection error "
        f"{result.rms_px:.3f} px, views covering {result.coverage:.0%} of the image.\n"
        "# Include it in the vehicle's configuration (include = [\"this file\"]), set\n"
        "# camera.mount_rpy_deg there, then measure the pixel noise: companion calibrate "
        "noise.\n\n"
        "[camera]\n"
        f"width = {c.width}\nheight = {c.height}\n"
        f"fx = {c.fx:.4f}\nfy = {c.fy:.4f}\ncx = {c.cx:.4f}\ncy = {c.cy:.4f}\n"
        f"distortion = [{dist}]   # OpenCV order: k1, k2, p1, p2, k3\n"
    )
