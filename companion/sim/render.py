"""The simulated camera: renders the world from a vehicle state and reports the truth.

Speed comes from warping each textured quad only into the bounding box of its visible
polygon (``cv2.warpPerspective`` on a region of interest), plain quads by ``fillPoly``,
and lens distortion by one ``cv2.remap`` with maps computed once (only when non-zero).
Pixel coordinates everywhere follow OpenCV: the centre of pixel (i, j) is at (i, j).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from companion.core.frames import ImageU8
from companion.core.stream_format import TruthBox, TruthCamera, TruthPose
from companion.sim.textures import sky_gradient
from companion.sim.trajectory import KinematicState
from companion.sim.world import Quad, World
from tracker.camera import CameraModel
from tracker.geometry import FloatArray

Z_NEAR_M = 0.01
EDGE_SAMPLES = 16  # points per edge when distortion bends straight edges
SHIFT = 4  # fillPoly sub-pixel bits


@dataclass(frozen=True, eq=False)
class Rendered:
    """One rendered frame with its truth (boxes of visible landmarks, poses)."""

    image: ImageU8
    boxes: tuple[TruthBox, ...]
    pose: TruthPose
    camera: TruthCamera


def clip_halfspace(points: FloatArray, normal: FloatArray, offset: float) -> FloatArray:
    """Sutherland-Hodgman: the part of a convex polygon where ``p . normal >= offset``."""
    if len(points) and float((points @ normal).min()) >= offset:
        return points  # nothing to clip
    out: list[FloatArray] = []
    n = len(points)
    for i in range(n):
        a, b = points[i], points[(i + 1) % n]
        da, db = float(a @ normal) - offset, float(b @ normal) - offset
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (b - a) * (da / (da - db)))  # the edge's crossing point
    return np.asarray(out, dtype=np.float64).reshape(-1, points.shape[1])


def clip_rect(poly: FloatArray, x0: float, y0: float, x1: float, y1: float) -> FloatArray:
    """A convex 2-D polygon clipped to the rectangle [x0, x1] x [y0, y1]."""
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    if lo[0] >= x0 and lo[1] >= y0 and hi[0] <= x1 and hi[1] <= y1:
        return poly  # already inside (the common case for landmarks)
    for normal, offset in (((1, 0), x0), ((-1, 0), -x1), ((0, 1), y0), ((0, -1), -y1)):
        if len(poly) == 0:
            break
        poly = clip_halfspace(poly, np.asarray(normal, dtype=np.float64), offset)
    return poly


def polygon_area(poly: FloatArray) -> float:
    """Shoelace area of a 2-D polygon."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


class Renderer:
    """Draws sky, ground, facades, poles, landmarks (far to near) for a camera model."""

    def __init__(self, camera: CameraModel, world: World) -> None:
        self.camera = camera
        self.world = world
        self.distorted = bool(np.any(camera.dist_coeffs != 0.0))
        self._margin = (0, 0)
        self._maps: tuple[np.ndarray, np.ndarray] | None = None
        if self.distorted:
            self._build_distortion_maps()
        mx, my = self._margin
        self.canvas_size = (camera.width + 2 * mx, camera.height + 2 * my)
        self.k_render = camera.matrix.copy()
        self.k_render[0, 2] += mx
        self.k_render[1, 2] += my
        self._sky = sky_gradient(*self.canvas_size)
        self._ones_cache: dict[tuple[int, int], np.ndarray] = {}

    def _build_distortion_maps(self) -> None:
        """For each output (distorted) pixel, where to read it in the pinhole canvas."""
        cam = self.camera
        xs, ys = np.meshgrid(np.arange(cam.width, dtype=np.float64),
                             np.arange(cam.height, dtype=np.float64))
        grid = np.stack([xs.ravel(), ys.ravel()], 1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-6)
        und = cv2.undistortPoints(
            grid, cam.matrix, cam.dist_coeffs, None, None, cam.matrix, criteria
        ).reshape(-1, 2)
        lim_x, lim_y = cam.width * 0.5, cam.height * 0.5
        und[:, 0] = np.clip(und[:, 0], -lim_x, cam.width - 1 + lim_x)
        und[:, 1] = np.clip(und[:, 1], -lim_y, cam.height - 1 + lim_y)
        mx = int(np.ceil(max(0.0, -und[:, 0].min(), und[:, 0].max() - (cam.width - 1)))) + 2
        my = int(np.ceil(max(0.0, -und[:, 1].min(), und[:, 1].max() - (cam.height - 1)))) + 2
        self._margin = (mx, my)
        map_x = (und[:, 0] + mx).reshape(cam.height, cam.width).astype(np.float32)
        map_y = (und[:, 1] + my).reshape(cam.height, cam.width).astype(np.float32)
        self._maps = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)

    def camera_pose(self, state: KinematicState) -> tuple[FloatArray, FloatArray]:
        """(camera position NED, R_ned_cam) for a vehicle state (camera at the body origin)."""
        r_ned_cam = state.r_ned_body @ self.camera.r_body_cam
        return np.asarray(state.position_ned_m, dtype=np.float64), r_ned_cam

    def render(self, state: KinematicState, extra: Sequence[Quad] = ()) -> Rendered:
        """The frame seen from ``state``; ``extra`` quads (distractors) are drawn, not truth."""
        pos, r = self.camera_pose(state)
        img = self._sky.copy()
        w = self.world
        for quad in [w.far_ground, w.ground, *self._far_to_near(w.facades, pos)]:
            self._draw(img, quad, r, pos)
        objects = [*w.poles, *(lm.quad for lm in w.landmarks), *extra]
        for quad in self._far_to_near(objects, pos):
            self._draw(img, quad, r, pos)
        if self._maps is not None:
            img = np.asarray(cv2.remap(img, self._maps[0], self._maps[1], cv2.INTER_LINEAR),
                             dtype=np.uint8)
        boxes = tuple(b for lm in w.landmarks if (b := self.truth_box(lm.quad, r, pos)))
        pose = TruthPose(*state.position_ned_m, *state.attitude_rpy_rad)
        camera = TruthCamera(state.position_ned_m, r)
        return Rendered(np.ascontiguousarray(img), boxes, pose, camera)

    @staticmethod
    def _far_to_near(quads: Sequence[Quad], pos: FloatArray) -> list[Quad]:
        return sorted(quads, key=lambda q: -float(np.linalg.norm(q.centre_ned - pos)))

    @staticmethod
    def _faces_camera(quad: Quad, pc: FloatArray, r: FloatArray) -> bool:
        n_cam = quad.normal_ned @ r  # R^T n as a row vector
        return bool(quad.two_sided or float(n_cam @ -pc[0]) > 0.0)

    def _draw(self, img: ImageU8, quad: Quad, r: FloatArray, pos: FloatArray) -> None:
        pc = (quad.corners_ned - pos) @ r  # camera-frame corners: R^T (p - c)
        if not self._faces_camera(quad, pc, r):
            return
        poly = clip_halfspace(pc, np.array([0.0, 0.0, 1.0]), Z_NEAR_M)
        if len(poly) < 3:
            return
        k = self.k_render
        uv = (poly @ k.T)[:, :2] / poly[:, 2:3]  # pinhole u = fx x/z + cx
        cw, ch = self.canvas_size
        uv = clip_rect(uv, -1.0, -1.0, float(cw), float(ch))
        if len(uv) < 3:
            return
        if quad.texture is None:
            pts = np.round(uv * (1 << SHIFT)).astype(np.int32)
            cv2.fillPoly(img, [pts], quad.colour_bgr, cv2.LINE_8, SHIFT)
            return
        lo, hi = np.floor(uv.min(axis=0)).astype(int), np.ceil(uv.max(axis=0)).astype(int)
        x0, y0 = max(0, int(lo[0])), max(0, int(lo[1]))
        x1, y1 = min(cw, int(hi[0]) + 1), min(ch, int(hi[1]) + 1)
        if x1 <= x0 or y1 <= y0:
            return
        th, tw = quad.texture.shape[:2]
        u_vec, v_vec = (pc[1] - pc[0]) / tw, (pc[3] - pc[0]) / th
        o_vec = pc[0] + 0.5 * u_vec + 0.5 * v_vec  # texture pixel (0, 0) centre
        h = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]]) @ (
            k @ np.column_stack([u_vec, v_vec, o_vec])  # H = T K [U V O]
        )
        size = (x1 - x0, y1 - y0)
        patch = cv2.warpPerspective(quad.texture, h, size, flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REPLICATE)
        # Exact coverage: a pixel belongs to the face when its centre maps inside the
        # texture (nearest-neighbour warp of an all-ones image).  fillPoly alone covers up
        # to a pixel too much; it is kept to exclude the mirror image of the plane behind
        # the camera, which the homography also maps into the texture.
        inside: np.ndarray = cv2.warpPerspective(
            self._ones(tw, th), h, size, flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )
        mask = np.zeros((size[1], size[0]), np.uint8)
        pts = np.round((uv - (x0, y0)) * (1 << SHIFT)).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, SHIFT)
        roi = img[y0:y1, x0:x1]  # a view: cv2.copyTo writes into img in place
        cv2.copyTo(patch, cv2.bitwise_and(mask, inside), roi)

    def _ones(self, width: int, height: int) -> np.ndarray:
        key = (width, height)
        if key not in self._ones_cache:
            self._ones_cache[key] = np.ones((height, width), np.uint8)
        return self._ones_cache[key]

    def image_outline(self, pc: FloatArray) -> FloatArray:
        """Image polygon of a camera-frame quad in front of the camera (with distortion)."""
        if not self.distorted:
            return self.camera.project_camera_points(pc)
        s = np.linspace(0.0, 1.0, EDGE_SAMPLES, endpoint=False)[:, None]
        edges = [pc[i] + s * (pc[(i + 1) % 4] - pc[i]) for i in range(4)]
        return self.camera.project_camera_points(np.concatenate(edges))

    def truth_box(self, quad: Quad, r: FloatArray, pos: FloatArray) -> TruthBox | None:
        """Box, corners and in-view share of a landmark facing the camera, else None."""
        pc = (quad.corners_ned - pos) @ r
        if np.any(pc[:, 2] <= Z_NEAR_M) or not self._faces_camera(quad, pc, r):
            return None
        outline = self.image_outline(pc)
        cam = self.camera
        inside = clip_rect(outline, 0.0, 0.0, cam.width - 1.0, cam.height - 1.0)
        full = polygon_area(outline)
        if len(inside) < 3 or full <= 0.0:
            return None
        frac = min(1.0, polygon_area(inside) / full)
        if frac <= 0.0:
            return None
        # clipping puts a crossing on the border up to an ulp outside (y = -1e-16, found by
        # tests/sim's any-pose property): the box is held to the image
        edge = (cam.width - 1.0, cam.height - 1.0)
        lo, hi = np.maximum(inside.min(axis=0), 0.0), np.minimum(inside.max(axis=0), edge)
        corners = cam.project_camera_points(pc)
        return TruthBox(quad.landmark_id, float(lo[0]), float(lo[1]), float(hi[0] - lo[0]),
                        float(hi[1] - lo[1]), corners, frac)
