"""Telemetry in recordings (stream format 2): ``companion record --autopilot`` writes the
autopilot's messages beside the frames, and ``companion replay`` hands the recorded
attitude to the solver through the fake autopilot (issue 25)."""

from __future__ import annotations

import bisect
import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.core.stream_format import read_meta
from companion.core.stream_io import read_telemetry, read_truth_pose
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig
from mavlink_bridge.vehicle import VehicleState
from tests.run_helpers import SIM_LAYER, fake_in_thread, synth
from tests.test_replay import replay

#: The deliberate error of the recorded autopilot's heading.
YAW_OFFSET_DEG = 8.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """3 s of the hover scenario recorded in real time beside a fake autopilot whose
    heading is 8 deg off, with the scenario's map beside it."""
    base = tmp_path_factory.mktemp("telemetry")
    sim = Simulator(load_scenario("hover"))

    def offset(t: float) -> VehicleState:
        s = sim.truth_fn(t)
        r, p, y = s.attitude_rpy_rad
        return dataclasses.replace(s, attitude_rpy_rad=(r, p, y + math.radians(YAW_OFFSET_DEG)))

    out = base / "v2"
    # the exact attitude plus the offset (no EKF-sized error): what is recorded is known
    config = FakeAutopilotConfig(endpoint="udpin:127.0.0.1:0", attitude_error=None)
    with fake_in_thread(config, offset) as fake:
        assert main(["record", "--config", str(SIM_LAYER), "--source", "sim:hover",
                     "--seconds", "3", "--out", str(out),
                     "--autopilot", f"udpout:127.0.0.1:{fake.local_port}"]) == 0
    ref = synth(base / "map", seconds=0.2, scenario="hover")  # the world's map and images
    shutil.copy(ref / "landmarks.geojson", out / "landmarks.geojson")
    shutil.copytree(ref / "landmarks.appearance", out / "landmarks.appearance")
    return out


def _recorded_yaw_error_deg(stream: Path) -> float:
    """Mean (recorded ATTITUDE yaw - true yaw) over the frames, from the files alone."""
    att = [(t, f["yaw"]) for t, name, f in read_telemetry(stream) if name == "ATTITUDE"]
    times = [t for t, _ in att]
    diffs = []
    for t_us, pose in read_truth_pose(stream).values():
        i = bisect.bisect_right(times, t_us) - 1
        if i >= 0:
            diffs.append(math.degrees(math.remainder(att[i][1] - pose.yaw_rad, math.tau)))
    return float(np.mean(diffs))


def test_record_with_an_autopilot_writes_telemetry_as_format_2(recorded: Path) -> None:
    assert read_meta(recorded).version == 2
    rows = read_telemetry(recorded)
    names = {name for _, name, _ in rows}
    assert {"ATTITUDE", "GLOBAL_POSITION_INT"} <= names, names
    attitude = [t for t, name, _ in rows if name == "ATTITUDE"]
    assert len(attitude) > 60, len(attitude)  # asked at 50 Hz for 3 s
    assert abs(_recorded_yaw_error_deg(recorded) - YAW_OFFSET_DEG) < 2.0  # time-aligned


def test_replay_gives_the_solver_the_recorded_attitude(tmp_path: Path, recorded: Path) -> None:
    """The attitude given is the recording's ATTITUDE (8 deg off in yaw), not the truth;
    without telemetry.csv the same frames get truth_pose.csv plus the stated noise, a draw
    of it ``--attitude-seed`` chooses."""
    status, s = replay(tmp_path, recorded)
    assert status == 0
    assert s["attitude"].startswith("the recording's ATTITUDE"), s["attitude"]
    recorded_n = sum(name == "ATTITUDE" for _, name, _ in read_telemetry(recorded))
    # each recorded message at most once, thinned to the asked 30 Hz: 30-54 of ~100 seen
    # (fewer when the loaded machine recorded fewer)
    assert 10 < s["telemetry_replayed"]["ATTITUDE"] <= recorded_n, s["telemetry_replayed"]
    expected = _recorded_yaw_error_deg(recorded)
    assert abs(s["attitude_error_deg"]["yaw_mean"] - expected) < 0.5, (s, expected)

    plain = tmp_path / "v1"
    shutil.copytree(recorded, plain)
    (plain / "telemetry.csv").unlink()
    status, s1 = replay(tmp_path / "plain", plain)
    assert status == 0
    assert s1["attitude"].startswith("truth_pose.csv with an autopilot's stated noise")
    assert s1["attitude"].endswith("error seed 0)"), s1["attitude"]
    assert abs(s1["attitude_error_deg"]["yaw_mean"]) < 3.0, s1["attitude_error_deg"]
    # another draw of that error: said, and different
    status, s2 = replay(tmp_path / "seeded", plain, "--attitude-seed", "5")
    assert status == 0
    assert s2["attitude"].endswith("error seed 5)"), s2["attitude"]
    assert s2["attitude_error_deg"] != s1["attitude_error_deg"]
