"""``companion run --config config/sitl-*.toml`` against the fake autopilot playing SITL,
and the ``--fly`` square's messages as the fake autopilot records them."""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.core.map_file import read_map
from companion.landmarks.geodesy import LocalFrame
from companion.settings import load_settings
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.factory import resolve
from companion.square import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    MAV_CMD_NAV_TAKEOFF,
    TYPE_MASK_POSITION_YAW,
    SquareFlight,
    SquarePlan,
    square_corners,
)
from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.vehicle import VehicleState
from tests.run_helpers import fake_in_thread as fake_thread

ROOT = Path(__file__).resolve().parents[2]


@contextmanager
def fake_in_thread(config: FakeAutopilotConfig) -> Iterator[FakeAutopilot]:
    """The fake autopilot on its own event loop (``companion run`` owns the main one),
    8 s into the survey: landmarks in view."""
    sim = Simulator(load_scenario("survey"))

    def truth(t_s: float) -> VehicleState:
        return sim.truth_fn(t_s + 8.0)

    with fake_thread(config, truth) as fake:
        yield fake


def run_args(config: str, port: int, tmp_path: Path, *extra: str) -> list[str]:
    return ["run", "--config", str(ROOT / "config" / config),
            "--set", f"mavlink.endpoint=udpout:127.0.0.1:{port}",
            "--set", "monitor.enabled=false", "--set", f'flightlog.dir="{tmp_path}"',
            "--set", "source.follow.truth_timeout_s=3.0", "--set", "source.follow.fps=10",
            *extra]


def test_the_px4_config_names_px4_sitls_link_home_and_map() -> None:
    """(The PX4 loop itself is proven against the fake in test_follow_truth.py.)"""
    s = load_settings([ROOT / "config" / "sitl-px4.toml"])
    assert (s.vehicle.profile, s.mavlink.endpoint, s.mavlink.output) == (
        "px4", "udpin:0.0.0.0:14540", "odometry")
    assert resolve(s.source).kind == "follow"
    home = LocalFrame(s.mavlink.origin_lat_deg, s.mavlink.origin_lon_deg, s.mavlink.origin_alt_m)
    ned = {lm.id: home.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m)
           for lm in read_map(s.landmarks.map_path)}
    assert ned["wall-01"] == pytest.approx([0.0, 12.0, -4.0], abs=0.01)


@pytest.mark.parametrize(("config", "profile"), [("sitl-ardupilot.toml", "ardupilot")])
def test_companion_run_with_the_sitl_config_closes_the_loop(
        tmp_path: Path, config: str, profile: str) -> None:
    with fake_in_thread(FakeAutopilotConfig(profile=profile)) as fake:  # type: ignore[arg-type]
        status = main(run_args(config, fake.local_port, tmp_path, "--seconds", "7"))
        accepted = len(fake.accepted())
        origin = fake.origin
    assert status == 0
    assert origin is not None and origin[0] == pytest.approx(
        -35.363261 if profile == "ardupilot" else 47.397742)
    assert accepted > 0, "no fix reached the autopilot"
    poses = [r for log in tmp_path.glob("run-*.jsonl")
             for r in map(json.loads, log.read_text().splitlines()) if "truth_error_m" in r]
    assert poses, "pose records carry no truth in follow mode"
    statuses = [r for log in tmp_path.glob("run-*.jsonl")
                for r in map(json.loads, log.read_text().splitlines()) if r["kind"] == "status"]
    assert statuses and {r["noise"] for r in statuses} == {"measured"}  # config/sim.toml's
    assert float(np.median([r["truth_error_m"] for r in poses])) < 0.3


def test_without_the_truth_message_run_fails_with_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with fake_in_thread(FakeAutopilotConfig(send_truth=False)) as fake:
        status = main(run_args("sitl-ardupilot.toml", fake.local_port, tmp_path,
                               "--seconds", "8"))
        sent = len(fake.vision)
    err = capsys.readouterr().err
    assert status == 1
    last = err.strip().splitlines()[-1]
    assert last.startswith("follow camera: the autopilot sends no SIM_STATE"), err
    assert "Traceback" not in err
    assert sent == 0, "fixes were sent without the simulator's truth"


async def test_fly_square_commands_and_position_targets() -> None:
    """GUIDED, arm, takeoff, then position targets at each corner (LOCAL_NED, yaw 90)."""
    plan = SquarePlan(side_m=5.0, altitude_m=3.0, leg_s=0.15, loops=1, climb_m_s=100.0,
                      settle_s=0.0, setpoint_rate_hz=20.0)
    async with FakeAutopilot(FakeAutopilotConfig()) as fake:
        bridge = PymavlinkBridge(MavlinkConfig(
            endpoint=f"udpout:127.0.0.1:{fake.local_port}", origin_lat_deg=47.0,
            origin_lon_deg=8.0, heartbeat_rate_hz=5.0))
        async with bridge:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 3.0)
            await asyncio.sleep(0.3)  # a HEARTBEAT with the armed bit
            flight = SquareFlight(bridge.link, bridge.latest, "ardupilot", plan)
            task = asyncio.create_task(flight.run())
            await asyncio.sleep(1.2)
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            await asyncio.sleep(0.1)
    cmds = [c["command"] for c in fake.commands]
    assert MAV_CMD_NAV_TAKEOFF in cmds
    assert MAV_CMD_DO_SET_MODE not in cmds and MAV_CMD_COMPONENT_ARM_DISARM not in cmds, \
        "the fake reports armed: no mode change or arming should be sent"
    targets = fake.position_targets
    assert targets, "no SET_POSITION_TARGET_LOCAL_NED arrived"
    seen = {(round(t["x"], 3), round(t["y"], 3), round(t["z"], 3)) for t in targets}
    assert seen == set(square_corners(plan))
    assert all(t["coordinate_frame"] == 1 and t["type_mask"] == TYPE_MASK_POSITION_YAW
               and math.isclose(t["yaw"], math.pi / 2, abs_tol=1e-6) for t in targets)


@pytest.mark.parametrize(("profile", "mode"), [("ardupilot", 4.0), ("px4", 6.0)])
async def test_fly_sets_the_mode_and_arms_when_disarmed(profile: str, mode: float) -> None:
    """Disarmed: GUIDED (ArduCopter custom mode 4) or OFFBOARD (PX4 main mode 6, after a
    setpoint stream), then arm; retried until armed or the timeout."""
    plan = SquarePlan(loops=1)
    async with FakeAutopilot(FakeAutopilotConfig(profile=profile)) as fake:  # type: ignore[arg-type]
        bridge = PymavlinkBridge(MavlinkConfig(
            endpoint=f"udpout:127.0.0.1:{fake.local_port}", origin_lat_deg=47.0,
            origin_lon_deg=8.0, heartbeat_rate_hz=5.0))
        async with bridge:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 3.0)
            flight = SquareFlight(bridge.link, lambda _n: None, profile, plan,
                                  arm_timeout_s=0.5, arm_retry_s=0.2)
            with pytest.raises(TimeoutError, match="not armed"):
                await flight.arm()
            await asyncio.sleep(0.1)
    modes = [c for c in fake.commands if c["command"] == MAV_CMD_DO_SET_MODE]
    arms = [c for c in fake.commands if c["command"] == MAV_CMD_COMPONENT_ARM_DISARM]
    assert modes and modes[0]["param1"] == 1.0 and modes[0]["param2"] == mode
    assert arms and arms[0]["param1"] == 1.0
    if profile == "px4":  # offboard refuses to engage without setpoints streaming first
        assert fake.position_targets
        assert fake.position_targets[0]["arrival_s"] < modes[0]["arrival_s"]
