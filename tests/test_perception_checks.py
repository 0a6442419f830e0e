"""Issue 25's perception checks: an acquisition is verified by the appearance it warps onto
the frame, a rotated plate keeps its corners, a track that lost its landmark leaves the
fix and is dropped, a light step is noticed, the corner sigma follows the fit."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import cv2
import numpy as np
import pytest

from companion.acquirers import Sighting
from companion.perception import Perception, PerceptionConfig
from companion.perception_types import Occupancy, Start, Track
from companion.sources.base import Frame
from tests.acquire.test_verify import scene
from tracker.acquire import homography_to, project_corners
from tracker.camera import CameraModel
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import MapLandmark, Observation, PoseFix


def perception(plate: np.ndarray, config: PerceptionConfig | None = None) -> Perception:
    lm = MapLandmark("p", (10.0, 0.0, 0.0), 1.2, 0.8, None, "other")
    return Perception(CameraModel(320, 240, 300.0, 300.0, 159.5, 119.5), [lm], {"p": plate},
                      config=config)


class Calls:
    """An acquirer that only notes the frames it was asked about."""

    def __init__(self) -> None:
        self.sights: list[Sighting] = []

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        self.sights.append(sight)
        return []


def track_at(p: Perception, corners: np.ndarray, box: tuple[float, float, float, float]
             ) -> Track:
    ref = p.matcher.references["p"]
    return Track("p", None, box, homography_to(ref, corners),  # type: ignore[arg-type]
                 corners=corners)


def test_an_acquisition_whose_appearance_is_not_there_is_refused() -> None:
    frame, plate, corners = scene()
    p = perception(plate)
    ref = p.matcher.references["p"]
    wrong = corners + np.array([-110.0, 60.0])
    start, sight = p.acquisition.starter.start, Sighting(frame, Occupancy())
    assert start("p", sight, (20.0, 120.0, 90.0, 90.0), homography_to(ref, wrong), wrong,
                 "search", []) == []
    right = start("p", sight, (115.0, 75.0, 90.0, 90.0), homography_to(ref, corners),
                  corners, "features", [])
    assert len(right) == 1 and right[0].event["appearance_correlation"] > 0.8


def test_a_rotated_plate_keeps_its_corners() -> None:
    """The tracker's box of a plate turned 35 deg is axis-aligned and about the plate's own
    size: it overlaps the aligned outline's box less than 0.5 (the old rule dropped the
    corners); the outline moved with the box matches the outline found."""
    frame, plate, corners = scene(angle_deg=35.0, noise=2.0)
    p = perception(plate)
    box = (160.0 - 45.0, 120.0 - 30.0, 90.0, 60.0)  # centred, unrotated size
    track = track_at(p, corners + np.array([1.5, -1.0]), box)  # last frame's outline, a bit off
    aligned = p.trackset.corners.align(track, frame, track.homography)  # type: ignore[arg-type]
    assert aligned is not None
    found = project_corners(p.matcher.references["p"], aligned)
    assert np.abs(found - corners).max() < 0.5


def test_a_track_that_lost_its_landmark_leaves_the_fix_and_is_dropped() -> None:
    frame, plate, corners = scene()
    p = perception(plate)
    wrong = corners + np.array([-110.0, 60.0])
    p.trackset.live["p"] = track_at(p, wrong, (20.0, 120.0, 90.0, 90.0))
    assert p.trackset.verify(frame) == []
    assert p.tracks["p"].verify_failures == 1
    assert p.observations(0) == []  # unverified: not in the fix
    events = p.trackset.verify(frame)
    assert "p" not in p.tracks
    assert events[0]["event"] == "lost" and "appearance" in events[0]["why"]


def test_a_track_on_its_landmark_passes_the_check_and_states_the_fit_sigma() -> None:
    frame, plate, corners = scene(noise=6.0)
    p = perception(plate)
    track = track_at(p, corners, (115.0, 75.0, 90.0, 90.0))
    p.trackset.live["p"] = track
    assert p.trackset.verify(frame) == [] and track.verify_failures == 0
    track.fit_sigma = 1e-4
    (obs,) = p.observations(0)
    model = p.noise.sigma(obs.corners_px)
    assert model is not None and obs.corner_sigma_px == model
    track.fit_sigma = 2.0 * model
    (obs,) = p.observations(0)
    scale = p.config.fit_sigma_scale  # the fit's (scaled), larger than the size model's
    assert obs.corner_sigma_px == scale * 2.0 * model
    track.fit_sigma = 3.0 * model  # beyond max_fit_sigma_ratio: the alignment sits wrong
    (obs,) = p.observations(0)
    assert obs.corners_px is None


def test_a_light_step_is_noticed_and_makes_acquisition_due() -> None:
    frame, plate, corners = scene()
    p = perception(plate)
    p.trackset.live["p"] = track_at(p, corners, (115.0, 75.0, 90.0, 90.0))
    p.acquisition.features = features = Calls()
    p.acquisition.acquired_frame = 100  # acquired, and a fix, last frame
    p.acquisition.last_fix_us = 3_333_333
    assert not p._light_step(frame)
    assert not p._light_step((frame * 0.9).astype(np.uint8))
    p.housekeeping(Frame(101, 3_366_666, frame))
    assert features.sights == []  # feature matching not due
    assert p._light_step(np.clip(frame * 1.6, 0, 255).astype(np.uint8))
    p.housekeeping(Frame(102, 3_399_999, frame))  # the light step's frame: due at once
    assert len(features.sights) == 1 and features.sights[0].seen.tracked == {"p"}


def test_a_track_without_corners_is_checked_where_its_box_is() -> None:
    """A box-only track (no corners this frame: a plate too small, or corners off) keeps the
    homography of its last corners: the check moves it to the tracker's box.  Checked at the
    stale homography, a plate that moved 40 px failed twice and its track was dropped."""
    frame, plate, corners = scene()
    p = perception(plate)
    before = corners + np.array([40.0, -25.0])  # where the corners were last found
    on_plate = track_at(p, before, (115.0, 75.0, 90.0, 90.0))  # the box is on the plate now
    on_plate.corners = None
    p.trackset.live["p"] = on_plate
    for _ in range(3):
        assert p.trackset.verify(frame) == []
    assert on_plate.verify_failures == 0
    off_plate = track_at(p, before, (20.0, 120.0, 90.0, 90.0))  # the box left the plate
    off_plate.corners = None
    p.trackset.live["p"] = off_plate
    assert p.trackset.verify(frame) == []
    events = p.trackset.verify(frame)
    assert "p" not in p.tracks and events[0]["event"] == "lost"


def test_a_track_whose_corners_miss_in_fixes_states_a_larger_sigma() -> None:
    """Issue 25: JPEG and biased real crops put corners off by more than the size model
    and the fit say.  A track's corners that missed the fix's reprojection in fixes from
    two plates state at least that RMS (times n / (n - 6)); a track whose corners matched
    keeps its sigma; one-plate fixes teach nothing.  A saturated plate's sigma grows with
    its saturated share."""
    from companion.corner_noise import POSE_PARAMETERS
    from tracker.pose.landmarks import landmark_corners_ned
    from tracker.pose.types import Observation, PoseFix

    lms = [MapLandmark("a", (10.0, -1.5, 0.0), 1.2, 0.8, None, "other"),
           MapLandmark("b", (10.0, 1.5, 0.0), 1.2, 0.8, None, "other")]
    cam = CameraModel(320, 240, 300.0, 300.0, 159.5, 119.5)
    plate = np.full((80, 120, 3), 128, np.uint8)
    plate[20:60, 30:90] = 20
    p = Perception(cam, lms, {"a": plate, "b": plate})
    pos, rpy = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    off = {"a": 0.0, "b": 1.0}  # b's corners 1 px off in x and y, every fix
    obs = []
    for lm in lms:
        true = cam.project_camera_points(cam.world_to_camera(
            landmark_corners_ned(lm), np.asarray(pos), rpy)) + off[lm.landmark_id]
        p.trackset.live[lm.landmark_id] = Track(lm.landmark_id, None,  # type: ignore[arg-type]
                                         (0.0, 0.0, 10.0, 10.0), None, corners=true)
        obs.append(Observation(centre_px=(0.0, 0.0), box_wh_px=(10.0, 10.0),
                               landmark_id=lm.landmark_id, corner_sigma_px=0.2,
                               corners_px=tuple((float(u), float(v)) for u, v in true)))
    fix = PoseFix(0, pos, rpy, np.eye(6), 90, ("a", "b"), "bearing_ls")
    one = PoseFix(0, pos, rpy, np.eye(6), 90, ("b",), "ippe")
    p.noise.learn(obs[1:], one, p.tracks)
    assert p.tracks["b"].residual_var is None  # one plate: nothing learnt
    for _ in range(30):
        p.noise.learn(obs, fix, p.tracks)
    expected = 1.0 * 16 / (16 - POSE_PARAMETERS)
    assert abs(p.tracks["b"].residual_var - expected) < 1e-6  # type: ignore[operator]
    assert p.noise.floor(obs[1], p.tracks).corner_sigma_px == pytest.approx(np.sqrt(expected))
    assert p.noise.floor(obs[0], p.tracks).corner_sigma_px == 0.2  # matched: unchanged
    p.tracks["a"].saturated = 0.5  # half its pixels saturated: 1 + 5.5 x 0.5
    assert p.noise.floor(obs[0], p.tracks).corner_sigma_px == pytest.approx(0.2 * 3.75)


def test_no_residual_floor_is_learnt_from_a_fix_with_a_young_cut_plate() -> None:
    """Issue 19's square: wall-01, acquired at the image's edge beside sign-01, shared 6-7
    fixes with it in its first frames; the floor learnt from their residuals then stated
    wall-01's corners at pixels for the 15 s it was alone (range 1-sigma 0.95-2.44 m where
    0.004 m otherwise), its fixes followed the autopilot's yaw and the flight failed, in
    each of the six flights that had those shared fixes and none of the others.  A fix
    with a plate still unsettled at the edge (``CornerNoise.unsettled``) teaches no track
    a floor; once that plate has been followed ``young_cut_frames``, it does."""
    lms = [MapLandmark("a", (10.0, -1.5, 0.0), 1.2, 0.8, None, "other"),
           MapLandmark("b", (10.0, 1.5, 0.0), 1.2, 0.8, None, "other")]
    cam = CameraModel(320, 240, 300.0, 300.0, 59.5, 119.5)  # a across the left edge
    plate = np.full((80, 120, 3), 128, np.uint8)
    plate[20:60, 30:90] = 20
    p = Perception(cam, lms, {"a": plate, "b": plate})
    obs = []
    for lm in lms:
        seen = cam.project_camera_points(cam.world_to_camera(
            landmark_corners_ned(lm), np.zeros(3), (0.0, 0.0, 0.0))) + 1.0  # 1 px off
        p.trackset.live[lm.landmark_id] = Track(lm.landmark_id, None,  # type: ignore[arg-type]
                                         (0.0, 0.0, 10.0, 10.0), None, corners=seen)
        obs.append(Observation(centre_px=(0.0, 0.0), box_wh_px=(10.0, 10.0),
                               landmark_id=lm.landmark_id, corner_sigma_px=0.2,
                               corners_px=tuple((float(u), float(v)) for u, v in seen)))
    assert p.noise.unsettled(p.tracks["a"]) and not p.noise.unsettled(p.tracks["b"])
    fix = PoseFix(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), np.eye(6), 90, ("a", "b"), "bearing_ls")
    for _ in range(10):
        p.noise.learn(obs, fix, p.tracks)
    assert p.tracks["a"].residual_var is None and p.tracks["b"].residual_var is None
    p.tracks["a"].frames = p.config.young_cut_frames  # followed a while: settled
    assert not p.noise.unsettled(p.tracks["a"])
    p.noise.learn(obs, fix, p.tracks)
    assert p.tracks["a"].residual_var is not None and p.tracks["b"].residual_var is not None


def test_a_track_whose_corners_the_pose_keeps_leaving_out_is_dropped() -> None:
    """docs/reliability.md finding 4: a re-acquired track kept corners 12.7 sigma off and
    the pose left them out of every fix; after ``max_pose_rejections`` fixes in a row it
    is dropped (to be acquired afresh); a track used in between starts counting again."""
    from tracker.pose.types import Observation, PoseFix

    _frame, plate, corners = scene()
    p = perception(plate, PerceptionConfig(max_pose_rejections=3))
    p.trackset.live["p"] = track_at(p, corners, (115.0, 75.0, 90.0, 90.0))
    obs = [Observation(centre_px=(0.0, 0.0), box_wh_px=(1.0, 1.0), landmark_id="p",
                       corners_px=tuple((float(u), float(v)) for u, v in corners))]
    without = PoseFix(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), np.eye(6), 90, ("q",), "ippe")
    with_p = dataclasses.replace(without, landmark_ids=("p",))
    drop = p.trackset.drop_rejected
    assert drop(obs, without) == [] and drop(obs, without) == []
    assert drop(obs, with_p) == [] and p.tracks["p"].pose_rejections == 0
    assert drop(obs, without) == [] and drop(obs, without) == []
    (event,) = drop(obs, without)
    assert "p" not in p.tracks and event["event"] == "lost" and "3 fixes" in event["why"]


def test_a_track_named_as_the_odd_one_of_three_is_counted_without_a_fix() -> None:
    """Of three landmarks one did not fit: no fix (too few to drop it), the solver names it
    (``NoFix.outlier``). Before, nothing counted it and a misaligned plate blocked every fix
    for as long as it was tracked (the coupled hover's first 7 s in CI, 2026-12-03); now it
    is dropped at ``max_pose_rejections`` like a plate the fixes leave out. A frame without
    a fix that names another landmark, or none, leaves its count alone."""
    from tracker.pose.types import NoFix, Observation

    _frame, plate, corners = scene()
    p = perception(plate, PerceptionConfig(max_pose_rejections=3))
    p.trackset.live["p"] = track_at(p, corners, (115.0, 75.0, 90.0, 90.0))
    obs = [Observation(centre_px=(0.0, 0.0), box_wh_px=(1.0, 1.0), landmark_id="p",
                       corners_px=tuple((float(u), float(v)) for u, v in corners))]
    named = NoFix(0, "landmarks 'p', 'q', 'r' disagree", outlier="p")
    drop = p.trackset.drop_rejected
    assert drop(obs, named) == [] and drop(obs, named) == []
    assert drop(obs, NoFix(0, "no fix")) == [] and p.tracks["p"].pose_rejections == 2
    assert drop(obs, NoFix(0, "disagree", outlier="q")) == []
    assert p.tracks["p"].pose_rejections == 2
    (event,) = drop(obs, named)
    assert "p" not in p.tracks and event["event"] == "lost"


def test_a_plate_cut_by_the_edge_gives_only_its_corners_inside_the_image() -> None:
    """Issue 19: a plate a fifth in view was left out of the fix (the square's 6-7 s gap);
    now its corners inside the image are measured, the extrapolated ones flagged, their
    sigma grown by 1 / sqrt(share in view).  A plate wholly in view is unchanged."""
    _frame, plate, corners = scene()
    p = perception(plate)
    whole = track_at(p, corners, (0.0, 0.0, 1.0, 1.0))
    p.trackset.live["p"] = whole
    [full] = p.observations(0)
    assert full.corners_measured is None and full.corners_px is not None
    cut_corners = corners + (np.array([320.0, 240.0]) - corners[0]) - 40.0  # TL 40 px inside
    p.trackset.live["p"] = track_at(p, cut_corners, (0.0, 0.0, 1.0, 1.0))
    p.trackset.live["p"].frames = p.config.young_cut_frames  # followed a while
    [cut] = p.observations(0)
    assert cut.corners_measured == (True, False, False, False)
    assert cut.corners_px is not None and np.allclose(cut.corners_px, cut_corners)
    assert cut.corner_sigma_px is not None and full.corner_sigma_px is not None
    assert cut.corner_sigma_px > 1.5 * full.corner_sigma_px


def test_a_cut_plates_corners_out_of_the_image_are_stated_as_weak_points() -> None:
    """Issue 19's hover at (6, 6): with one corner of the one plate in view, the fix rested
    on that corner's bearing (1.6-3.9 m stated) and the strict fake drifted on its IMU.  The
    corners the outline puts outside the image are given too, at
    ``cut_extrapolated_sigma_rel`` of its size (never under the measured corners' sigma)
    when the outline out of view is settled (carried by the cut plate's alignment from an
    outline of the plate mostly in view; one found afresh on a cut plate is not): 0 leaves
    them out as before, and a plate wholly in view has none."""
    _frame, plate, corners = scene()
    size = float(np.sqrt(abs(cv2.contourArea(corners.astype(np.float32)))))
    cut_corners = corners + (np.array([320.0, 240.0]) - corners[0]) - 40.0  # TL 40 px inside
    for rel, want in ((0.05, 0.05 * size), (0.0, None)):
        p = perception(plate, dataclasses.replace(PerceptionConfig(),
                                                  cut_extrapolated_sigma_rel=rel))
        track = track_at(p, cut_corners, (0.0, 0.0, 1.0, 1.0))
        p.trackset.live["p"] = track
        track.frames = p.config.young_cut_frames  # followed a while
        [found] = p.observations(0)  # not settled (found afresh on the cut plate): none
        assert found.corners_measured == (True, False, False, False)
        assert found.extrapolated_sigma_px is None
        track.outline_held = True  # carried by the cut plate's alignment from a settled outline
        [cut] = p.observations(0)
        assert cut.corners_measured == (True, False, False, False)
        assert cut.extrapolated_sigma_px == (None if want is None else pytest.approx(want))
        assert cut.corner_sigma_px is not None and cut.corner_sigma_px < 0.05 * size
        p.trackset.live["p"] = track_at(p, corners, (0.0, 0.0, 1.0, 1.0))
        [whole] = p.observations(0)
        assert whole.extrapolated_sigma_px is None


def test_a_plate_crossing_the_edge_states_its_fit_and_a_part_box_gives_no_fix() -> None:
    """Issue 19's square, one frame in three: wall-01 coming into view (64-96 %) had a fit
    sigma over its whole outline, part of it out of view, that failed the size model, so it
    had no corners, and the box-only fallback took its tracker's box, which held the part in
    view when it was seated: fixes 1.2 m off.  A plate crossing the image's edge keeps its
    corners, at the larger of the size model and its fit; a ``partial_box`` track gives no
    box-only observation.  A whole plate with such a fit is still refused its corners."""
    _frame, plate, corners = scene()
    p = perception(plate)
    mostly = corners + np.array([325.0 - corners[:, 0].max(), 0.0])  # 5 px out on the right
    track = track_at(p, mostly, (100.0, 80.0, 60.0, 60.0))
    p.trackset.live["p"] = track
    track.frames = p.config.young_cut_frames
    model = p.noise.sigma([(float(u), float(v)) for u, v in mostly]) or 0.0
    track.fit_sigma = 10.0 * p.config.max_fit_sigma_ratio * model  # fails the size model
    assert not p.noise.fits(track)
    [edge] = p.observations(0)
    assert edge.corners_px is not None and edge.corners_measured is None
    assert edge.corner_sigma_px is not None and edge.corner_sigma_px > 5.0 * model
    whole = track_at(p, corners, (100.0, 80.0, 60.0, 60.0))
    whole.fit_sigma, whole.frames = track.fit_sigma, track.frames
    p.trackset.live["p"] = whole
    [box_only] = p.observations(0)  # its corners refused: its box stands for it
    assert box_only.corners_px is None
    whole.partial_box = True  # the box holds the part that was in view when seated
    assert p.observations(0) == []


def test_a_young_cut_plate_states_its_corners_no_better_than_its_unsettled_outline() -> None:
    """Issue 19's square: a plate acquired while cut by the edge had its first outlines
    pixels off; its lone fixes were 0.3-1.7 m off at a stated 0.02-0.14 m and the strict
    fake's estimate followed them.  In a cut plate's first ``young_cut_frames`` its
    corners are stated at ``young_cut_sigma_rel`` of the outline's size at least (the fix
    still comes), also when the plate is mostly in view but crosses the edge (the square's
    sign-01 leaving (6, 6)); a plate inside the image, however new, and an old cut plate
    keep their own sigma."""
    _frame, plate, corners = scene()
    config = dataclasses.replace(PerceptionConfig(), young_cut_frames=9, young_cut_sigma_rel=0.1)
    p = perception(plate, config)
    cut_corners = corners + (np.array([320.0, 240.0]) - corners[0]) - 40.0  # TL 40 px inside
    track = track_at(p, cut_corners, (0.0, 0.0, 1.0, 1.0))
    p.trackset.live["p"] = track
    floor = 0.1 * float(np.sqrt(abs(cv2.contourArea(corners.astype(np.float32)))))
    assert floor > 3.0  # the plate's own sigma is well under a tenth of its size
    sigmas = []
    for frames in (0, 8, 9, 30):
        track.frames = frames
        [obs] = p.observations(0)
        assert obs.corners_measured == (True, False, False, False)
        sigmas.append(obs.corner_sigma_px)
    assert sigmas[0] == sigmas[1] == pytest.approx(floor)
    assert sigmas[2] == sigmas[3] and sigmas[2] is not None and sigmas[2] < 3.0
    mostly = corners + np.array([325.0 - corners[:, 0].max(), 0.0])  # 5 px out on the right
    track = track_at(p, mostly, (0.0, 0.0, 1.0, 1.0))
    p.trackset.live["p"] = track
    [edge] = p.observations(0)
    assert edge.corners_measured is None  # all four, young: the outline's floor
    assert edge.corner_sigma_px == pytest.approx(floor)
    track.frames = 9
    [edge] = p.observations(0)
    assert edge.corner_sigma_px is not None and edge.corner_sigma_px < 3.0
    p.trackset.live["p"] = track_at(p, corners, (0.0, 0.0, 1.0, 1.0))  # whole, new
    [whole] = p.observations(0)
    assert whole.corners_measured is None and whole.corner_sigma_px is not None
    assert whole.corner_sigma_px < 3.0


def test_a_box_that_disagreed_with_its_outline_gives_no_box_only_fix() -> None:
    """The alignment finds the plate, the tracker's box sits 60 px off it: the corners are
    dropped (which of the two wandered is not known), and the box is not used alone
    either (a box 20-30 px off a plate gave a fix 2.8 m off, survey frame 84) until an
    alignment holds again; an undisputed box without corners still is."""
    frame, plate, corners = scene()
    p = perception(plate)
    track = track_at(p, corners, (115.0 + 60.0, 75.0, 90.0, 90.0))
    assert p.trackset.corners.align(track, frame, track.homography) is None  # type: ignore[arg-type]
    assert track.disputed
    track.corners = None
    p.trackset.live["p"] = track
    assert p.observations(0) == []
    track.disputed = False  # a box-only track that never disagreed: its box is observed
    (obs,) = p.observations(0)
    assert obs.corners_px is None and obs.centre_px == (175.0 + 45.0, 75.0 + 45.0)
    track.disputed = True
    track.box = (115.0, 75.0, 90.0, 90.0)  # back on the plate: the alignment holds again
    p.trackset.corners.follow(track, frame, track.box)
    assert track.corners is not None and not track.disputed
