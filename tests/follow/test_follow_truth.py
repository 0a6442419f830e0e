"""Follow mode: truth telemetry parsing, interpolation, the fake's truth streams, the source.

Every test names what it proves; the fake autopilot flies the survey scenario's trajectory
(``Simulator.truth_fn``) so the camera's rendered pose can be compared with the truth.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from collections.abc import AsyncIterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import SourceError
from companion.follow import (
    FollowCameraSource,
    TruthSample,
    add_sample,
    command_sender,
    slerp,
    state_at,
    truth_sample,
)
from companion.landmarks.geodesy import LocalFrame
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.config import FollowConfig
from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.messages import euler_to_quaternion
from mavlink_bridge.telemetry import SimTruth, Telemetry, convert
from tracker.geometry import rotation_from_rpy

ORIGIN = LocalFrame(47.3769, 8.5417, 408.0)
FAST = FollowConfig(truth_timeout_s=1.5, stale_ms=200.0)


def decoded(msg: Any) -> dict[str, Any]:
    """A message packed and parsed by pymavlink, as the link sees it."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out = mav.parse_char(msg.pack(mav))
    assert out is not None
    return dict(out.to_dict())


# ------------------------------------------------------------------ parsing
def test_sim_state_prefers_the_degE7_extension_fields() -> None:  # noqa: N802
    msg = mavlink.MAVLink_sim_state_message(
        1, 0, 0, 0, 0.1, -0.2, 1.5, 0, 0, -9.8, 0, 0, 0, 47.0, 8.0, 500.25, 0, 0,
        1.0, 2.0, -0.5, 473769123, 85417456)
    v = convert("SIM_STATE", decoded(msg))
    assert isinstance(v, SimTruth)
    assert (v.lat_deg, v.lon_deg) == pytest.approx((47.3769123, 8.5417456), abs=1e-9)
    assert v.alt_m == pytest.approx(500.25)
    assert v.velocity_ned_m_s == pytest.approx((1.0, 2.0, -0.5))
    assert v.attitude_rpy_rad == pytest.approx((0.1, -0.2, 1.5), abs=1e-6)


def test_old_ardupilot_sim_state_degE7_in_float_fields_is_recognised() -> None:  # noqa: N802
    """ArduPilot before lat_int wrote lat*1e7 into the float 'lat' (degrees by the spec)."""
    msg = mavlink.MAVLink_sim_state_message(
        1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, -353632621.0, 1491652300.0, 584.0, 0, 0,
        0, 0, 0, 0, 0)
    v = convert("SIM_STATE", decoded(msg))
    assert v.lat_deg == pytest.approx(-35.3632621, abs=1e-5)
    assert v.lon_deg == pytest.approx(149.16523, abs=1e-5)


def test_simstate_has_position_and_attitude_but_no_altitude() -> None:
    msg = mavlink.MAVLink_simstate_message(0.05, 0.02, -3.0, 0, 0, -9.8, 0, 0, 0,
                                           -353632621, 1491652300)
    v = convert("SIMSTATE", decoded(msg))
    assert v.alt_m is None and v.quaternion_wxyz is None
    assert (v.lat_deg, v.lon_deg) == pytest.approx((-35.3632621, 149.16523), abs=1e-9)
    assert truth_sample(Telemetry("SIMSTATE", 1, 1, 0, v), ORIGIN) is None


def test_hil_state_quaternion_units_and_attitude() -> None:
    q = euler_to_quaternion(0.1, -0.05, 2.0)
    msg = mavlink.MAVLink_hil_state_quaternion_message(
        123456, list(q), 0, 0, 0, 473977420, 85455940, 488123, 150, -250, 30,
        0, 0, 0, 0, -1000)
    v = convert("HIL_STATE_QUATERNION", decoded(msg))
    assert (v.lat_deg, v.lon_deg, v.alt_m) == pytest.approx((47.397742, 8.545594, 488.123))
    assert v.velocity_ned_m_s == pytest.approx((1.5, -2.5, 0.3))
    assert v.attitude_rpy_rad == pytest.approx((0.1, -0.05, 2.0), abs=1e-6)
    assert v.time_usec == 123456


def test_truth_sample_converts_to_ned_about_the_origin() -> None:
    lat, lon, alt = ORIGIN.to_wgs84(12.0, -7.0, -4.0)
    v = SimTruth(float(lat), float(lon), float(alt), (0.0, 0.0, 0.5), None, None)
    s = truth_sample(Telemetry("SIM_STATE", 1, 1, 42, v), ORIGIN)
    assert s is not None and s.t_ns == 42
    assert s.position_ned_m == pytest.approx([12.0, -7.0, -4.0], abs=1e-6)


# ------------------------------------------------------------------ interpolation
def sample(t_ns: int, pos: tuple[float, float, float], yaw: float) -> TruthSample:
    return TruthSample(t_ns, np.asarray(pos, float),
                       np.asarray(euler_to_quaternion(0.0, 0.0, yaw)), np.zeros(3))


def test_interpolation_between_samples_is_linear_in_position_and_slerp_in_attitude() -> None:
    s = [sample(0, (0, 0, -4), 0.0), sample(20_000_000, (1, 2, -4), 0.4)]
    st = state_at(s, 5_000_000, 0)
    assert st is not None
    assert st.position_ned_m == pytest.approx((0.25, 0.5, -4.0))
    assert st.attitude_rpy_rad[2] == pytest.approx(0.1)


def test_yaw_interpolates_the_short_way_across_pi() -> None:
    s = [sample(0, (0, 0, 0), math.pi - 0.1), sample(10, (0, 0, 0), -math.pi + 0.1)]
    st = state_at(s, 5, 0)
    assert st is not None and abs(abs(st.attitude_rpy_rad[2]) - math.pi) < 1e-6


def test_extrapolation_is_bounded_and_gaps_are_not_bridged() -> None:
    s = [sample(0, (0, 0, 0), 0.0), sample(10_000_000, (1, 0, 0), 0.0)]
    st = state_at(s, 15_000_000, 10_000_000)
    assert st is not None and st.position_ned_m[0] == pytest.approx(1.5)
    assert state_at(s, 25_000_000, 10_000_000) is None
    assert state_at(s, 5_000_000, 0, max_gap_ns=5_000_000) is None


def test_a_burst_read_after_a_stall_keeps_only_its_newest_sample() -> None:
    """Samples sent over a 200 ms stall are read within microseconds: interpolating between
    them would put 20 ms of motion into 10 us; the newest of the burst has the right stamp."""
    samples: deque[TruthSample] = deque()
    add_sample(samples, sample(0, (0, 0, 0), 0.0))
    for k in range(1, 11):  # sent every 20 ms over the stall, all read at ~200 ms
        add_sample(samples, sample(200_000_000 + k * 10_000, (0.2 * k / 10, 0, 0), 0.0))
    assert [s.t_ns for s in samples] == [0, 200_100_000]
    st = state_at(samples, 100_000_000, 0)
    assert st is not None and st.position_ned_m[0] == pytest.approx(0.1, abs=1e-3)


def test_steady_samples_are_never_merged() -> None:
    samples: deque[TruthSample] = deque()
    for k in range(5):
        add_sample(samples, sample(k * 20_000_000, (k, 0, 0), 0.0))
    assert len(samples) == 5


def test_slerp_matches_rotation_of_intermediate_angle() -> None:
    q0 = np.asarray(euler_to_quaternion(0.3, 0.0, 0.0))
    q1 = np.asarray(euler_to_quaternion(0.9, 0.0, 0.0))
    q = slerp(q0, q1, 0.5)
    assert q == pytest.approx(np.asarray(euler_to_quaternion(0.6, 0.0, 0.0)), abs=1e-9)


def test_quaternion_from_rpy_agrees_with_tracker_geometry() -> None:
    from companion.follow import rotation_from_quaternion

    rpy = (0.2, -0.4, 2.5)
    r = rotation_from_quaternion(np.asarray(euler_to_quaternion(*rpy)))
    assert r == pytest.approx(rotation_from_rpy(*rpy), abs=1e-12)


# ------------------------------------------------------------------ with the fake autopilot
@pytest.fixture(scope="module")
def sim() -> Simulator:
    return Simulator(load_scenario("survey"))


async def _wired(sim: Simulator, profile: str = "ardupilot", **fake_kw: Any
                 ) -> AsyncIterator[tuple[FakeAutopilot, PymavlinkBridge]]:
    o = sim.scenario.origin
    # the follow camera's own behaviour: the fake streams everything unasked unless a test
    # asks for the strict fake (which sends the truth only when asked)
    fake_kw.setdefault("streams", "all")
    cfg = replace(FakeAutopilotConfig(profile=profile), **fake_kw)  # type: ignore[arg-type]
    async with FakeAutopilot(cfg, truth=sim.truth_fn) as ap:
        bridge = PymavlinkBridge(MavlinkConfig(
            endpoint=f"udpout:127.0.0.1:{ap.local_port}", profile=profile,  # type: ignore[arg-type]
            origin_lat_deg=o.lat, origin_lon_deg=o.lon, origin_alt_m=o.alt_m,
            origin_retry_s=0.05, heartbeat_rate_hz=5.0, link_timeout_s=0.6))
        async with bridge:
            bridge.report_health("ok")
            yield ap, bridge


def flight_time_s(ap: FakeAutopilot, t_us: int) -> float:
    return (t_us * 1000 - ap.start_ns) / 1e9


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
async def test_rendered_pose_follows_the_simulators_truth(sim: Simulator, profile: str) -> None:
    """Frames show the world from the true pose at their stamp (degE7 lat/lon: ~1 cm); the
    strict fake sends the truth only because the camera asks for it."""
    async for ap, bridge in _wired(sim, profile, streams="strict"):
        src = FollowCameraSource(sim, bridge, ORIGIN, profile, FAST,
                                 request=command_sender(bridge))
        try:
            errors, yaw_err = [], []
            for _ in range(12):
                frame = await src.recv()
                state = src.rendered_state(frame.index)
                assert state is not None and src.truth(frame.index) is not None
                truth = sim.state_at(flight_time_s(ap, frame.t_us))
                errors.append(math.dist(state.position_ned_m, truth.position_ned_m))
                yaw_err.append(abs(state.attitude_rpy_rad[2] - truth.attitude_rpy_rad[2]))
            # truth is stamped on arrival (docs/sitl.md): a sample delayed by a busy event
            # loop shows the world a few cm behind for one frame; the rest must be exact
            assert sorted(errors)[len(errors) // 2] < 0.01, errors
            assert sum(e > 0.02 for e in errors) <= 1 and max(errors) < 0.10, errors
            assert max(yaw_err) < 1e-3
            assert frame.image.shape == (480, 640, 3)
            asked = [c for c in ap.commands if c["command"] == 511]
            assert asked, "the truth stream was never requested (SET_MESSAGE_INTERVAL)"
        finally:
            src.close()


@pytest.mark.parametrize(("profile", "missing"), [("ardupilot", "SIM_STATE"),
                                                  ("px4", "HIL_STATE_QUATERNION")])
async def test_a_vehicle_without_truth_is_a_one_line_error_naming_the_message(
        sim: Simulator, profile: str, missing: str) -> None:
    async for _ap, bridge in _wired(sim, profile, send_truth=False):
        src = FollowCameraSource(sim, bridge, ORIGIN, profile, FAST)
        with pytest.raises(SourceError) as err:
            await src.recv()
        text = str(err.value)
        assert f"no {missing}" in text and "\n" not in text
        assert src.failure is err.value and src.status.delivered == 0
        src.close()


async def test_simstate_alone_is_refused_because_it_has_no_altitude(sim: Simulator) -> None:
    periods = tuple(p for p in FakeAutopilotConfig().periods_s if p[0] != "SIM_STATE")
    async for _ap, bridge in _wired(sim, periods_s=periods):
        src = FollowCameraSource(sim, bridge, ORIGIN, "ardupilot", FAST)
        with pytest.raises(SourceError, match="SIMSTATE arrives but no SIM_STATE"):
            await src.recv()
        src.close()


async def test_stale_truth_stops_the_frames_until_it_comes_back(sim: Simulator) -> None:
    """The truth stream stops for 1 s: no frame shows a time the truth did not cover."""
    async for ap, bridge in _wired(sim):
        src = FollowCameraSource(sim, bridge, ORIGIN, "ardupilot", FAST)
        try:
            frames = [await src.recv() for _ in range(3)]
            ap.drop_link(1.0)
            dropped_at = time.monotonic_ns()
            frames += [await asyncio.wait_for(src.recv(), 5.0) for _ in range(6)]
        finally:
            src.close()
        assert src.status.stalls == 1 and src.status.skip_reasons["stale-truth"] > 0
        gaps_s = np.diff([f.t_us for f in frames]) / 1e6
        assert gaps_s.max() > 0.8, "frames kept coming while the truth was gone"
        # at most max_extrapolation_ms (100) past the last truth, then nothing until it is back
        shown_after_drop_s = [(f.t_us * 1000 - dropped_at) / 1e9 for f in frames]
        assert not [t for t in shown_after_drop_s if 0.15 < t < 0.95], shown_after_drop_s
        assert max(shown_after_drop_s) > 1.0, "frames never resumed"
        for f in frames:
            state = src.rendered_state(f.index)
            truth = sim.state_at(flight_time_s(ap, f.t_us))
            assert state is not None
            assert math.dist(state.position_ned_m, truth.position_ned_m) < 0.02


async def test_a_companion_that_falls_behind_gets_the_frame_due_now(sim: Simulator) -> None:
    """A live camera keeps taking frames while the companion is busy; the ones not read are
    gone.  Before, the follow camera handed out the missed slots one by one, each stamped
    with its old time: under load every fix was stale and the coupled hover's EKF failed."""
    async for _ap, bridge in _wired(sim):
        src = FollowCameraSource(sim, bridge, ORIGIN, "ardupilot", FAST)
        try:
            first = await src.recv()
            await asyncio.sleep(0.5)  # busy for 15 frames' time
            asked_ns = time.monotonic_ns()
            late = await src.recv()
        finally:
            src.close()
    period_ns = 1e9 / src.fps
    shown_ns = asked_ns - FAST.delay_ms * 1e6
    assert late.t_us * 1000 > shown_ns - 1.5 * period_ns, (asked_ns, late.t_us)
    assert late.index - first.index >= 14
    assert src.status.skip_reasons["late"] == late.index - first.index - 1
