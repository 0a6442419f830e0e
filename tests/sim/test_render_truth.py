"""Truth geometry: projected corners and boxes match the rendered pixels within 1 px."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from companion.sim.render import Renderer
from companion.sim.trajectory import KinematicState
from companion.sim.world import World
from tracker.camera import CameraModel

from .conftest import flat_landmark


def landmark_mask(camera: CameraModel, world: World, state: KinematicState) -> np.ndarray:
    """Pixels that change by more than half the landmark's contrast when it is added.

    (Half, because lens distortion resamples the frame bilinearly: a pixel half covered by
    the landmark is half way between the two colours.)
    """
    with_lm = Renderer(camera, world).render(state).image
    empty = World([], world.config, world.seed)
    without = Renderer(camera, empty).render(state).image
    diff = np.abs(with_lm.astype(int) - without.astype(int)).sum(axis=2)
    contrast = np.median(diff[diff > 0])
    return diff > contrast / 2


def signed_distance(poly: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Distance of each (row, col) pixel centre to the outline, positive inside."""
    contour = poly.reshape(-1, 1, 2).astype(np.float32)
    return np.array([cv2.pointPolygonTest(contour, (float(x), float(y)), True)
                     for y, x in pixels])


def boundary_distance(poly: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    return np.abs(signed_distance(poly, pixels))


def check_mask_matches(mask: np.ndarray, outline: np.ndarray, min_pixels: int = 500) -> None:
    """Every pixel the landmark changed has its centre inside the outline and every pixel
    centre inside it was changed, but for pixels within 1 px of the outline (edge
    sampling).  The truth is exact: fillPoly's raster only picks the pixels to check (it
    also takes some centres up to ~1 px outside an edge, which are not the landmark's)."""
    raster = np.zeros(mask.shape, np.uint8)
    cv2.fillPoly(raster, [np.round(outline * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    assert mask.sum() > min_pixels  # the landmark really is in the picture
    candidates = np.argwhere(mask != raster.astype(bool))
    if len(candidates):
        signed = signed_distance(outline, candidates)
        inside = signed >= 0.0
        changed = mask[candidates[:, 0], candidates[:, 1]]
        wrong = changed != inside
        if wrong.any():
            assert np.abs(signed[wrong]).max() <= 1.0


def test_corners_and_box_match_rendered_pixels(one_landmark_world, east_state, camera) -> None:
    out = Renderer(camera, one_landmark_world).render(east_state)
    assert [b.landmark_id for b in out.boxes] == ["L1"]
    box = out.boxes[0]
    mask = landmark_mask(camera, one_landmark_world, east_state)
    check_mask_matches(mask, box.corners_px)
    ys, xs = np.nonzero(mask)
    assert abs(xs.min() - box.x) <= 1 and abs(xs.max() - (box.x + box.w)) <= 1
    assert abs(ys.min() - box.y) <= 1 and abs(ys.max() - (box.y + box.h)) <= 1
    assert box.in_view_frac == 1.0


def test_corner_order_is_tl_tr_br_bl(one_landmark_world, east_state, camera) -> None:
    c = Renderer(camera, one_landmark_world).render(east_state).boxes[0].corners_px
    assert c[0, 0] < c[1, 0] and c[3, 0] < c[2, 0]  # left of right
    assert c[0, 1] < c[3, 1] and c[1, 1] < c[2, 1]  # top above bottom


def test_truth_with_lens_distortion(one_landmark_world, east_state) -> None:
    cam = CameraModel(distortion=(-0.3, 0.1, 0.001, -0.001, 0.0), mount_rpy_deg=(0, -5, 0))
    r = Renderer(cam, one_landmark_world)
    state = dataclasses.replace(east_state, position_ned_m=(2.0, 4.0, -4.2))  # off-centre
    box = r.render(state).boxes[0]
    mask = landmark_mask(cam, one_landmark_world, state)
    pc = (one_landmark_world.landmarks[0].quad.corners_ned - state.position_ned_m) @ (
        r.camera_pose(state)[1])
    check_mask_matches(mask, r.image_outline(pc))
    ys, xs = np.nonzero(mask)
    assert abs(xs.min() - box.x) <= 1 and abs(ys.max() - (box.y + box.h)) <= 1


def test_flat_landmark_seen_from_above(make_landmark) -> None:
    world = World([make_landmark("F", (5.0, 0.0, 0.0), (2.0, 1.0), None)], seed=1)
    down = CameraModel(mount_rpy_deg=(0.0, -90.0, 0.0))
    state = KinematicState(0.0, (5.2, 0.1, -10.0), (0, 0, 0), (0.0, 0.0, 0.3))
    box = Renderer(down, world).render(state).boxes[0]
    check_mask_matches(landmark_mask(down, world, state), box.corners_px)
    # facing north (yaw 0.3 rad): the landmark's north (top) edge is up in the image
    assert box.corners_px[0, 1] < box.corners_px[3, 1]


def test_back_face_and_out_of_view_are_not_truth(one_landmark_world, camera) -> None:
    behind = KinematicState(0.0, (0.0, 20.0, -4.0), (0, 0, 0), (0.0, 0.0, -np.pi / 2))
    assert Renderer(camera, one_landmark_world).render(behind).boxes == ()
    away = KinematicState(0.0, (0.0, 0.0, -4.0), (0, 0, 0), (0.0, 0.0, -np.pi / 2))
    assert Renderer(camera, one_landmark_world).render(away).boxes == ()


def test_partly_in_view_is_clipped(one_landmark_world, camera) -> None:
    # yaw so that the landmark straddles the right image border
    state = KinematicState(0.0, (0.0, 0.0, -4.0), (0, 0, 0), (0.0, 0.0, np.deg2rad(62.0)))
    box = Renderer(camera, one_landmark_world).render(state).boxes[0]
    assert 0.0 < box.in_view_frac < 1.0
    assert box.corners_px[:, 0].max() > camera.width - 1
    assert abs(box.x + box.w - (camera.width - 1)) < 1e-6


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    north=st.floats(-3.0, 3.0), east=st.floats(6.0, 20.0), down=st.floats(-6.0, -1.0),
    yaw_deg=st.floats(70.0, 110.0), pitch_deg=st.floats(-15.0, 15.0),
    roll_deg=st.floats(-10.0, 10.0), size=st.floats(0.5, 3.0),
)
# found by a full-suite run: fillPoly's raster took a centre 1.012 px outside an edge
@example(north=-1.3671875, east=11.7890625, down=-1.5, yaw_deg=105.71875,
         pitch_deg=11.7890625, roll_deg=-4.75, size=3.0)
def test_truth_matches_pixels_for_random_poses(
    north: float, east: float, down: float, yaw_deg: float, pitch_deg: float,
    roll_deg: float, size: float,
) -> None:
    """Property: wherever a fully visible landmark lands, its corners bound its pixels."""
    lm = flat_landmark("P", (north, east, -3.0), (size, size * 0.7), 270.0)
    world = World([lm], seed=0)
    cam = CameraModel(mount_rpy_deg=(0.0, -5.0, 0.0))
    att = (np.deg2rad(roll_deg), np.deg2rad(pitch_deg), np.deg2rad(yaw_deg))
    state = KinematicState(0.0, (0.0, 0.0, down), (0, 0, 0), att)
    boxes = Renderer(cam, world).render(state).boxes
    assume(len(boxes) == 1 and boxes[0].in_view_frac == 1.0)
    mask = landmark_mask(cam, world, state)
    assume(mask.sum() > 60)
    check_mask_matches(mask, boxes[0].corners_px, min_pixels=60)
