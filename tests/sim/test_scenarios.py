"""Scenario files, the simulator and the simulated camera source."""

from __future__ import annotations

import dataclasses
import functools
import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.core.stream_io import read_truth_boxes, read_truth_pose
from companion.errors import ConfigError
from companion.sim.scenario import SCENARIO_DIR, load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource
from companion.sim.synth import synth_stream
from companion.sim.trajectory import KinematicState
from companion.sources.base import EndOfStream, Frame
from companion.sources.files import RecordedStreamSource

REQUIRED = ("hover", "survey", "illumination_ramp", "sudden_light", "occlusion")


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIO_DIR.glob("*.toml")))
def test_builtin_scenarios_load_and_see_landmarks(name: str) -> None:
    sim = Simulator(load_scenario(name))
    _, truth = sim.render(0)
    assert len(truth.boxes) >= 1
    assert truth.pose is not None and truth.camera is not None


def test_required_scenarios_exist() -> None:
    assert set(REQUIRED) <= {p.stem for p in SCENARIO_DIR.glob("*.toml")}


def test_survey_sees_three_landmarks_at_a_time() -> None:
    sim = Simulator(load_scenario("survey"))
    counts = [len(sim.render(i, t_s=t)[1].boxes) for i, t in enumerate(range(8, 20, 2))]
    assert max(counts) == 3 and min(counts) >= 2


def test_leave_and_reenter_view() -> None:
    sim = Simulator(load_scenario("leave_reenter"))
    seen = [len(sim.render(0, t_s=t)[1].boxes) for t in (1.0, 8.0, 20.0)]
    assert seen[0] >= 1 and seen[1] == 0 and seen[2] == seen[0]


def test_same_seed_same_frames_other_seed_other_noise() -> None:
    sim = Simulator(load_scenario("illumination_ramp"))
    a, _ = sim.render(7)
    b, _ = Simulator(load_scenario("illumination_ramp")).render(7)
    assert np.array_equal(a, b)
    c, _ = sim.with_overrides(seed=99).render(7)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("seconds = -1.0", r"seconds: expected a number > 0"),
        ("fps = \"fast\"", r"fps: expected a number"),
        ("[camera]\nwidht = 3", r"camera.widht: unknown key"),
        ("[[effects]]\nkind = \"fog\"", r"effects\[0\].kind: expected one of"),
        ("[[effects]]\nkind = \"shadow\"\nlandmark_id = \"zz\"", r"unknown landmark_id 'zz'"),
    ],
)
def test_bad_scenario_is_one_line_error(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f'landmarks = "{SCENARIO_DIR.parent / "landmarks.geojson"}"\n{text}\n')
    with pytest.raises(ConfigError, match=message) as info:
        Simulator(load_scenario(str(path)))
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_unknown_scenario_name_lists_builtins() -> None:
    with pytest.raises(ConfigError, match=r"built-in: .*survey"):
        load_scenario("no_such_scenario")


async def test_sim_source_fast_mode_and_truth() -> None:
    sim = Simulator(dataclasses.replace(load_scenario("hover"), seconds=0.2, fps=10.0))
    source = SimCameraSource(sim, realtime=False)
    frames = [await source.recv(), await source.recv()]
    assert [f.index for f in frames] == [0, 1] and frames[1].t_us == 100_000
    assert frames[0].image.shape == (480, 640, 3) and frames[0].camera_id == "sim0"
    assert source.truth(1) is not None and source.scenario_time_s(frames[1]) == 0.1
    with pytest.raises(EndOfStream):
        await source.recv()


async def test_sim_source_realtime_is_paced_on_the_monotonic_clock() -> None:
    sim = Simulator(dataclasses.replace(load_scenario("hover"), seconds=1.0, fps=50.0))
    source = SimCameraSource(sim, realtime=True)
    frames = [await source.recv() for _ in range(3)]
    assert source.t0_us is not None
    ts = [source.scenario_time_s(f) for f in frames]
    assert all(b > a for a, b in itertools.pairwise(ts))
    assert source.status.delivered == 3


async def test_synth_writes_a_stream_that_replays_with_truth(tmp_path: Path) -> None:
    sim = Simulator(dataclasses.replace(load_scenario("occlusion"), seconds=0.5, fps=6.0))
    assert synth_stream(sim, tmp_path / "s") == 3
    source = RecordedStreamSource(tmp_path / "s", realtime=False)
    for index in range(3):
        frame = await source.recv()
        image, truth = sim.render(index)
        assert np.array_equal(frame.image, image)  # lossless PNG, deterministic render
        boxes = read_truth_boxes(tmp_path / "s")[index]
        assert [b.landmark_id for b in boxes] == [b.landmark_id for b in truth.boxes]
        assert np.allclose(boxes[0].corners_px, truth.boxes[0].corners_px, atol=1e-3)
    _, pose = read_truth_pose(tmp_path / "s")[2]
    assert pose.east_m == pytest.approx(sim.state_at(2 / 6.0).position_ned_m[1], abs=1e-6)
    assert source.meta.origin is not None and source.meta.provenance["scenario"] == "occlusion"


def test_occlusion_scenario_reports_the_covered_share() -> None:
    sim = Simulator(load_scenario("occlusion"))
    share = {t: next(b.occluded_frac for b in sim.render(0, t_s=t)[1].boxes
                     if b.landmark_id == "wall-02") for t in (2.0, 7.0, 10.0, 13.0, 20.0)}
    assert share[2.0] == 0.0 and share[20.0] == 0.0
    assert share[7.0] == pytest.approx(0.4) and share[10.0] == pytest.approx(0.8)
    assert share[13.0] == pytest.approx(0.4)


def test_autopilot_truth_matches_the_camera_truth() -> None:
    sim = Simulator(load_scenario("survey"))
    _, truth = sim.render(300)  # t = 10 s
    ap = sim.autopilot_truth(10.0)
    assert truth.pose is not None
    assert ap.position_ned_m == (truth.pose.north_m, truth.pose.east_m, truth.pose.down_m)
    assert ap.attitude_rpy_rad == (truth.pose.roll_rad, truth.pose.pitch_rad, truth.pose.yaw_rad)
    assert ap.velocity_ned_m_s[0] == pytest.approx(1.6)
    readings = [sim.autopilot_truth(10.0 + k / 1000).range_m for k in range(200)]
    good = [r for r in readings if r <= sim.rangefinder.config.max_range_m]
    assert 0 < len(readings) - len(good) < 20  # 2 % dropouts read out of range
    assert np.mean(good) == pytest.approx(4.0 / np.cos(ap.attitude_rpy_rad[1]), abs=0.01)


async def test_sim_source_shares_a_given_clock() -> None:
    from companion.sources.base import monotonic_us

    sim = Simulator(dataclasses.replace(load_scenario("survey"), seconds=60.0, fps=30.0))
    t0 = monotonic_us() - 10_000_000  # e.g. the fake autopilot started 10 s ago
    source = SimCameraSource(sim, realtime=True, t0_us=t0)
    frame = await source.recv()
    t_s = source.scenario_time_s(frame)
    assert 10.0 <= t_s < 10.5 and frame.index == round(t_s * 30)
    assert source.status.skipped == 0
    truth = source.truth(frame.index)
    assert truth is not None and truth.pose is not None
    assert truth.pose.north_m == pytest.approx(sim.state_at(t_s).position_ned_m[0])


async def test_sim_source_that_falls_behind_drops_late_frames() -> None:
    sim = Simulator(dataclasses.replace(load_scenario("hover"), seconds=10.0, fps=2000.0))
    source = SimCameraSource(sim, realtime=True)
    frames = [await source.recv() for _ in range(3)]
    assert frames[2].index - frames[0].index > 2  # rendering takes longer than 0.5 ms
    assert source.status.skip_reasons["late"] == frames[2].index - 2


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    pos=st.tuples(st.floats(-60, 60), st.floats(-60, 60), st.floats(-80, 2)),
    att=st.tuples(st.floats(-3.2, 3.2), st.floats(-1.6, 1.6), st.floats(-3.2, 3.2)),
)
def test_any_pose_renders_without_error(
    pos: tuple[float, float, float], att: tuple[float, float, float]
) -> None:
    """Looking anywhere from anywhere (even underground) gives a frame and sane truth."""
    sim = _distorted_sim()
    out = sim.renderer.render(KinematicState(0.0, pos, (0, 0, 0), att))
    assert out.image.shape == (480, 640, 3) and out.image.dtype == np.uint8
    for box in out.boxes:
        assert 0 <= box.x <= 639 and 0 <= box.y <= 479 and 0 < box.in_view_frac <= 1
        assert box.x + box.w <= 639 + 1e-6 and box.y + box.h <= 479 + 1e-6


@functools.cache
def _distorted_sim() -> Simulator:
    return Simulator(load_scenario("survey_distorted"))


def short_survey() -> Simulator:
    return Simulator(dataclasses.replace(load_scenario("survey"), seconds=2.0, fps=30.0))


async def rendered_elsewhere(source: SimCameraSource, count: int,
                             during: Callable[[], None] = lambda: None) -> list[Frame]:
    """``count`` frames of a source rendering in its own process (closed after them), each
    checked against the same frame rendered here; ``during`` runs once it has started."""
    try:
        await source.start()
        during()
        frames = [await source.recv() for _ in range(count)]
    finally:
        source.close()
    for frame in frames:
        image, _ = source.sim.render(frame.index)
        assert np.array_equal(frame.image, image), frame.index
    return frames


async def test_sim_source_in_its_own_process_renders_the_same_frames() -> None:
    """Rendering out of the companion's process (issue 23) gives the in-process frames."""
    source = SimCameraSource(short_survey(), realtime=False, own_process=True)
    await rendered_elsewhere(source, 3)
    assert source.render_cpu_s == 0.0 and source.render_cpu_elsewhere_s > 0.0


async def test_frames_from_the_rendering_process_are_the_companions_own() -> None:
    """In real time a frame is rendered ahead while the last one is in use; frames come back
    through shared memory slots (issue 23): a frame delivered must not change when a later
    one is rendered into its slot, and closing the source removes the block."""
    shm = Path("/dev/shm")
    def blocks() -> set[Path]:  # shared memory blocks (not the pool's semaphores)
        return set(shm.glob("psm_*")) if shm.is_dir() else set()
    before = blocks()
    made: list[int] = []
    source = SimCameraSource(short_survey(), realtime=True, own_process=True)
    frames = await rendered_elsewhere(source, 6, lambda: made.append(len(blocks() - before)))
    assert made == [1]
    indices = [f.index for f in frames]
    assert indices == sorted(set(indices)) and len(set(i % 2 for i in indices)) == 2
    assert len(blocks()) == len(before)


async def test_frames_come_through_the_pipe_where_no_shared_memory_may_be_made(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Shared memory is a file in /dev/shm: under a file size limit smaller than the slots
    (tests/test_flightlog_faults.py's demo runs with 16 kB) the frames come pickled through
    the pool's pipe instead, the same frames."""
    import companion.sim.source as source_module

    monkeypatch.setattr(source_module.resource, "getrlimit", lambda _which: (16_000, -1))
    source = SimCameraSource(short_survey(), realtime=False, own_process=True)
    assert source._slots is None
    assert len(await rendered_elsewhere(source, 3)) == 3
