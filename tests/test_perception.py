"""Perception on rendered frames of the simulated world: acquire, track, solve, against truth."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from companion.acquirers import Sighting
from companion.demo import map_landmarks
from companion.perception import Perception, PerceptionConfig, SideSensors
from companion.perception_types import Start
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from tracker.acquire import AcquireConfig
from tracker.boxes import box_iou
from tracker.detector import Detector
from tracker.pose.config import PoseConfig
from tracker.pose.types import AttitudeSample, PoseFix


@dataclass(frozen=True)
class Hit:
    box: tuple[float, float, float, float]
    category: str
    score: float

#: Feature matching off (no reference has that many keypoints): SIFT finds these plates by
#: itself, and the detector tests are about the detector's path.
NO_FEATURES = AcquireConfig(min_inliers=10_000)


def flight(scenario: str, frames: range, attitude_error_rad: tuple[float, float, float] = (
        0.0, 0.0, 0.0), **kw: Any) -> tuple[Simulator, Perception, list[Any]]:
    """Run perception over rendered frames with the true attitude (plus
    ``attitude_error_rad``; the default sigmas); results with truth."""
    sim = Simulator(dataclasses.replace(load_scenario(scenario), seconds=60))
    landmarks, references = map_landmarks(sim)
    truth_at: dict[int, Any] = {}

    def sensors(t_us: int) -> SideSensors:
        s = sim.state_at(t_us / 1e6)
        rpy = np.add(s.attitude_rpy_rad, attitude_error_rad)
        return SideSensors(attitude=AttitudeSample(t_us, *map(float, rpy)))

    perception = Perception(sim.scenario.camera, landmarks, references, sensors=sensors, **kw)
    out = []
    for i in frames:
        image, truth = sim.render(i)
        truth_at[i] = truth
        frame = Frame(i, round(i * 1e6 / sim.fps), image)
        result = perception.process(frame)
        perception.housekeeping(frame)
        out.append((result, truth, sim.state_at(i / sim.fps)))
    return sim, perception, out


def test_survey_fixes_match_the_truth_and_say_how_good_they_are() -> None:
    _, _, out = flight("survey", range(180, 240))
    fixes = [(r.fix, st) for r, _, st in out if isinstance(r.fix, PoseFix)]
    assert len(fixes) >= 40  # acquisition within a few frames, then a fix per frame
    errors = [np.linalg.norm(np.subtract(f.position_ned_m, st.position_ned_m)) for f, st in fixes]
    assert np.sqrt(np.mean(np.square(errors))) < 0.15  # metres, at about 12 m
    for fix, st in fixes:
        sigma = np.sqrt(np.trace(np.asarray(fix.covariance)[:3, :3]))
        err = np.linalg.norm(np.subtract(fix.position_ned_m, st.position_ned_m))
        assert np.isfinite(fix.covariance).all() and err < 6 * sigma + 0.05


def test_no_track_for_a_landmark_out_of_view() -> None:
    sim, perception, out = flight("survey", range(180, 200))
    visible = {b.landmark_id for _, truth, _ in out for b in truth.boxes if b.in_view_frac > 0}
    assert perception.tracks, "nothing was acquired: the test would prove nothing"
    assert set(perception.tracks) <= visible
    # what the solver is told of the corners: their sigma and the outline's common scale
    obs = [o for o in perception.observations(199) if o.corners_px is not None]
    assert obs, "no corners: the rest would prove nothing"
    for o in obs:
        assert o.corner_sigma_px == perception.noise.sigma(o.corners_px)
        assert o.corner_scale_sigma_px == perception.config.corner_scale_sigma_px
    perception.config = dataclasses.replace(perception.config, corner_scale_sigma_px=0.2)
    assert all(o.corner_scale_sigma_px == 0.2 for o in perception.observations(199)
               if o.corners_px is not None)
    # the outline modes: the solver's unless a mixed-plane plate's are set for a lossy
    # frame (every plate here aligns on the mixed plane: ecc_grey_from_ratio is off)
    assert all(o.corner_mode_sigma_rel is None for o in obs)
    rel = (0.9, 0.8, 0.7, 1.1, 0.6, 0.7, 0.8, 1.2)
    perception.noise.config = dataclasses.replace(perception.noise.config,
                                                  lossy_mixed_corner_mode_sigma_rel=rel)
    assert all(o.corner_mode_sigma_rel is None for o in perception.observations(199)), \
        "the rendered frames are lossless: the pose's modes"
    frame = Frame(200, round(200 * 1e6 / sim.fps), sim.render(200)[0], lossy=True)
    perception.process(frame)
    lossy = [o for o in perception.observations(200) if o.corners_px is not None]
    assert lossy, "no corners on the lossy frame: the rest would prove nothing"
    assert all(o.corner_mode_sigma_rel == rel for o in lossy)


def test_a_detector_hit_restarts_a_track_when_the_reference_aligns_there() -> None:
    sim = Simulator(dataclasses.replace(load_scenario("survey"), seconds=60))
    _image, truth = sim.render(200)
    box = next(b for b in truth.boxes if b.in_view_frac == 1.0)
    category = next(lm.category for lm in sim.world.landmarks
                    if lm.landmark_id == box.landmark_id)
    hits = [Hit((box.x, box.y, box.w, box.h), category, 0.9)]
    _, _perception, out = flight("survey", range(200, 203), detect=lambda _img: hits,
                                 acquire_config=NO_FEATURES)
    events = [e for r, _, _ in out for e in r.events]
    assert {"event": "acquired", "landmark": box.landmark_id, "by": "detector"}.items() <= \
        next(e for e in events if e.get("by") == "detector").items()


def test_the_committed_detector_starts_tracks_on_the_right_landmarks() -> None:
    """With nothing tracked and no fix, the real detector (the committed model) finds the
    street's landmarks; each is matched to the map by category and aligned reference, and
    its track sits on the landmark's true box."""
    _, perception, out = flight("street", range(300, 303), detect=Detector().detect,
                                acquire_config=NO_FEATURES)
    started = {e["landmark"] for r, _, _ in out for e in r.events
               if e.get("event") == "acquired" and e.get("by") == "detector"}
    assert len(started) >= 2, started
    truth = {b.landmark_id: b for b in out[-1][1].boxes}
    for lid in started:
        b = truth[lid]
        assert box_iou(perception.tracks[lid].box, (b.x, b.y, b.w, b.h)) > 0.5, lid


def test_a_frame_of_another_size_is_a_bad_frame_not_a_crash() -> None:
    sim = Simulator(load_scenario("survey"))
    landmarks, references = map_landmarks(sim)
    perception = Perception(sim.scenario.camera, landmarks, references)
    result = perception.process(Frame(0, 0, np.zeros((240, 320, 3), np.uint8)))
    assert result.bad_frame and result.fix is None
    assert "320x240" in (result.no_fix_reason or "")


@pytest.mark.parametrize("scenario", ["survey"])
def test_acquisition_never_invents_a_landmark(scenario: str) -> None:
    """Every track is on a landmark in view, its corners inside the image within 1 px of
    the truth's: at the start the first wall is 0.23 in view, cut by the image's edge, and
    taken by its features on that part (issue 19)."""
    _, _, out = flight(scenario, range(0, 30))
    for result, truth, _ in out:
        in_view = {b.landmark_id: b for b in truth.boxes if b.in_view_frac > 0.0}
        for track in result.tracks:
            assert track.landmark_id in in_view, track.landmark_id
            true = in_view[track.landmark_id].corners_px
            assert true is not None and track.corners is not None
            true_px, seen = np.asarray(true), np.asarray(track.corners)
            inside = (true_px[:, 0] >= 3) & (true_px[:, 0] <= 636) & \
                (true_px[:, 1] >= 3) & (true_px[:, 1] <= 476)
            assert inside.any()
            assert np.abs(seen[inside] - true_px[inside]).max() < 1.0, track.landmark_id


def test_small_plates_corners_carry_a_larger_sigma() -> None:
    """Each observation's corner sigma follows its plate's width in the image:
    pose.pixel_sigma_px at perception.corner_sigma_ref_px, (ref / width) ** exponent
    elsewhere, and the configured sigma for every plate with exponent 0."""
    sim = Simulator(load_scenario("survey"))
    landmarks, references = map_landmarks(sim)
    perception = Perception(sim.scenario.camera, landmarks, references,
                            pose_config=PoseConfig(pixel_sigma_px=0.2))

    def plate(width: float) -> tuple[tuple[float, float], ...]:
        return ((100.0, 100.0), (100.0 + width, 100.0), (100.0 + width, 160.0), (100.0, 160.0))

    sigma = perception.noise.sigma
    assert sigma(plate(100.0)) == pytest.approx(0.2)
    assert sigma(plate(50.0)) == pytest.approx(0.2 * 2.0**0.8)
    assert (sigma(plate(200.0)) or 1.0) < 0.2
    assert sigma(None) is None
    flat = Perception(sim.scenario.camera, landmarks, references,
                      config=PerceptionConfig(corner_sigma_exponent=0.0),
                      pose_config=PoseConfig(pixel_sigma_px=0.2))
    assert flat.noise.sigma(plate(37.0)) == pytest.approx(0.2)
    perception.close()
    flat.close()


def test_a_plate_at_the_edge_of_a_rectified_frame_carries_a_larger_corner_sigma() -> None:
    """Rectifying a barrel-distorted frame stretches its edges by ``s`` (rectified px per
    raw px): a plate drawn ``w`` px wide there was imaged ``w / s`` px wide, so its corners
    get the sigma of that narrower plate, times ``s``: ``sigma(w) * s ** (1 + exponent)``."""
    sim = Simulator(load_scenario("survey_distorted"))
    landmarks, references = map_landmarks(sim)
    perception = Perception(sim.scenario.camera, landmarks, references,
                            pose_config=PoseConfig(pixel_sigma_px=0.2))

    def plate(x: float, y: float) -> tuple[tuple[float, float], ...]:
        return ((x - 40, y - 30), (x + 40, y - 30), (x + 40, y + 30), (x - 40, y + 30))

    assert perception._rectify is not None
    centre = perception.noise.sigma(plate(319.5, 239.5))
    assert centre == pytest.approx(0.2 * (100 / 80) ** 0.8, rel=1e-3)
    s = perception._rectify.scale_at((580.0, 420.0))
    assert s > 1.2
    assert perception.noise.sigma(plate(580.0, 420.0)) == pytest.approx(centre * s**1.8,
                                                                        rel=1e-6)
    assert perception.noise.stretch(plate(580.0, 420.0)) == s  # the outline's scale error too
    assert perception.noise.stretch(plate(319.5, 239.5)) == pytest.approx(1.0, abs=1e-3)
    perception.close()


@pytest.mark.parametrize("error_deg", [(15.0, 0.0, 0.0), (0.0, 0.0, 30.0)],
                         ids=["roll 15", "yaw 30"])
def test_a_wrong_attitude_is_rejected_with_an_event_and_the_fixes_stay_true(
    error_deg: tuple[float, float, float],
) -> None:
    """The autopilot's attitude 15 deg off in roll or 30 deg in yaw (6 sigma of the
    default prior): one or two plates with corners fix the pose alone, so the prior is
    dropped (an event, counted) and the fixes stay on the truth (RMSE 0.049 m; with the
    exact attitude 0.030 m)."""
    _, perception, out = flight("survey", range(180, 240),
                                attitude_error_rad=tuple(np.deg2rad(error_deg)))
    fixes = [(r.fix, st) for r, _, st in out if isinstance(r.fix, PoseFix)]
    assert len(fixes) >= 40
    rejected = [f for f, _ in fixes if f.attitude_prior == "rejected"]
    assert len(rejected) >= 0.9 * len(fixes)
    events = [e for r, _, _ in out for e in r.events if e["event"] == "attitude prior rejected"]
    # (a fix the temporal gate then holds back was rejected too: counted, not returned)
    assert len(events) == perception.attitude_rejections >= len(rejected)
    assert events[0]["detail"].startswith("attitude prior rejected: ")
    errors = [np.linalg.norm(np.subtract(f.position_ned_m, st.position_ned_m)) for f, st in fixes]
    assert np.sqrt(np.mean(np.square(errors))) < 0.15
    perception.close()


def test_an_over_exposed_plates_corners_are_not_used() -> None:
    """sudden_light hovers before one plate; from 12 s (frame 360) the light is at 160 %
    and over half the plate's pixels saturate, which pulled its corners 0.4 px off
    (docs/pose.md).  Its corners then stay out of the pose: one plate without corners
    gives at most a weak fix from its box's size (``size_bearing``, issue 19; before it,
    no fix).  Before, in normal light, the same track gives fixes from its corners."""
    _, perception, out = flight("sudden_light", range(320, 400))
    before = [r for r, _, _ in out[:40]]
    after = [r for r, _, _ in out[45:]]  # from frame 365
    assert sum(isinstance(r.fix, PoseFix) for r in before) >= 20
    assert all(t.corners is not None for r in after for t in r.tracks), \
        "the alignment lost the plate: the test would not show the saturation rule"
    assert after and all(r.fix is None or r.fix.solver == "size_bearing" for r in after)
    assert all(r.fix is not None or "unobservable" in (r.no_fix_reason or "") for r in after)
    assert all(r.fix.solver.startswith("ippe") for r in before if r.fix is not None)
    perception.close()


class Calls:
    """Stands in for acquirers: notes which was asked, on which image; starts nothing."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, np.ndarray]] = []
        self.name = "features"

    def named(self, name: str) -> Calls:
        other = Calls()
        other.calls, other.name = self.calls, name
        return other

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        self.calls.append((self.name, sight.image))
        return []


def test_housekeeping_sees_rectified_frames_even_ones_process_let_go() -> None:
    """With a distorted camera, acquisition must look at the rectified frame: the one
    ``process`` made, or -- when housekeeping lags behind what ``process`` keeps, or never
    had the frame -- one it rectifies itself, never the raw distorted frame."""
    sim = Simulator(load_scenario("survey_distorted"))
    landmarks, references = map_landmarks(sim)
    perception = Perception(sim.scenario.camera, landmarks, references)
    perception.acquisition.features = features = Calls()
    raw = sim.render(3)[0]
    perception.housekeeping(Frame(3, 100_000, raw))  # a frame process never saw
    assert perception._rectify is not None
    rectified = perception._rectify(raw)
    assert [c for c, _ in features.calls] == ["features"]
    assert np.array_equal(features.calls[0][1], rectified)
    assert not np.array_equal(rectified, raw)
    perception.close()


def test_with_tracks_running_housekeeping_takes_one_heavy_step_per_call() -> None:
    """Feature matching, the detector and the template search cost 6-45 ms of CPU each:
    while tracks run (their frames carry fixes), one per housekeeping call, in turns
    (issue 23); with no track, all at once for the quickest start."""
    sim = Simulator(dataclasses.replace(load_scenario("survey"), seconds=60))
    landmarks, references = map_landmarks(sim)
    image = sim.render(3)[0]

    def run(tracks: dict[str, Any], calls_n: int) -> list[list[str]]:
        perception = Perception(sim.scenario.camera, landmarks, references,
                                detect=lambda _img: [])
        acq, calls = perception.acquisition, Calls()
        acq.features, acq.detector, acq.search = calls.named("features"), \
            calls.named("detector"), calls.named("search")
        perception.trackset.live.update(tracks)
        per_call = []
        for i in range(calls_n):
            before = len(calls.calls)
            perception.housekeeping(Frame(i, 1_000_000 + i * 33_333, image))
            per_call.append([c for c, _ in calls.calls[before:]])
        perception.close()
        return per_call

    # a running track is only its place here (the snapshot keeps the boxes); no fix: lost,
    # and features are due at once
    spread = run({"running": SimpleNamespace(box=(0.0, 0.0, 20.0, 20.0))}, 5)
    assert spread == [["features"], ["detector"], ["search"], ["detector"], ["search"]]
    assert run({}, 1) == [["features", "detector", "search"]]
