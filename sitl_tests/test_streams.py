"""The streams the companion needs, against the strict fake (nothing streams until asked).

Proves: the strict fake sends no ATTITUDE to a companion that does not ask; the companion
asks on link-up and gets ATTITUDE within 2 s; after an autopilot reboot (which forgets every
interval) it asks again and gets ATTITUDE within 2 s of the autopilot's return; a stream the
configuration needs and the autopilot never sends is a warning: one log line, one
STATUSTEXT, the status's ``warnings``, and requests repeated with back-off.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from pathlib import Path

import pytest

from companion.autopilot import BridgeSink
from companion.sensors import SensorHistory
from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.streams import needed_streams
from sitl_tests.harness import Flight, sitl_settings, wait_until
from tracker.pose.config import PoseConfig

ORIGIN = {"origin_lat_deg": 47.39, "origin_lon_deg": 8.54, "origin_alt_m": 400.0}


def asked(rangefinder: bool = False) -> tuple[tuple[str, float], ...]:
    return tuple((s.name, s.rate_hz) for s in needed_streams(15.0, rangefinder=rangefinder))


async def until(pred: object, timeout_s: float) -> float | None:
    """Seconds until ``pred()`` holds (polled every 10 ms), None on timeout."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if pred():  # type: ignore[operator]
            return time.monotonic() - t0
        await asyncio.sleep(0.01)
    return None


def bridge_to(fake: FakeAutopilot, streams: tuple[tuple[str, float], ...]) -> PymavlinkBridge:
    return PymavlinkBridge(MavlinkConfig(endpoint=f"udpout:127.0.0.1:{fake.local_port}",
                                         streams=streams, **ORIGIN))  # type: ignore[arg-type]


async def test_a_companion_that_does_not_ask_gets_no_attitude() -> None:
    """The strict fake is as quiet as a real port (this is why no old test noticed)."""
    async with FakeAutopilot(FakeAutopilotConfig()) as fake, bridge_to(fake, ()) as bridge:
        bridge.report_health("ok")
        assert await bridge.wait_link(True, 3.0)
        await asyncio.sleep(2.0)
        assert bridge.latest("HEARTBEAT") is not None
        assert bridge.latest("ATTITUDE") is None, "the strict fake streamed ATTITUDE unasked"


async def test_attitude_within_2s_of_link_up_and_again_after_a_reboot() -> None:
    async with FakeAutopilot(FakeAutopilotConfig()) as fake:
        async with bridge_to(fake, asked()) as bridge:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 3.0)
            first = await until(lambda: bridge.latest("ATTITUDE") is not None, 2.0)
            assert first is not None, "no ATTITUDE within 2 s of link-up"
            await asyncio.sleep(1.0)
            silent_s = 1.0
            fake.reboot(silent_s)
            assert fake.streams.periods.keys() == {"HEARTBEAT"}, "a reboot kept the intervals"
            t_reboot = time.monotonic()

            def fresh() -> bool:  # an ATTITUDE of the new boot (time_boot_ms restarted)
                item = bridge.latest("ATTITUDE")
                return item is not None and item.value.time_boot_ms < 5000 \
                    and item.received_ns > t_reboot * 1e9
            back = await until(fresh, silent_s + 2.0)
            assert back is not None, "no ATTITUDE within 2 s of the autopilot's return"
            report = bridge.stream_report()
    assert back - silent_s <= 2.0
    att = [p for n, p in fake.streams.asked if n == "ATTITUDE"]
    assert len(att) >= 2 and att[-1] == pytest.approx(1 / 15.0, rel=0.01), fake.streams.asked
    assert report["ATTITUDE"]["requests"] >= 2
    print(f"ATTITUDE {first:.2f} s after link-up; {back - silent_s:.2f} s after the reboot's "
          f"return; {len(att)} requests")


async def test_a_needed_stream_that_never_comes_is_a_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    """DISTANCE_SENSOR with a range finder configured, on an autopilot without one."""
    caplog.set_level(logging.WARNING, logger="mavlink_bridge.streams")
    cfg = FakeAutopilotConfig(absent=("DISTANCE_SENSOR",))
    async with FakeAutopilot(cfg) as fake:
        async with bridge_to(fake, asked(rangefinder=True)) as bridge:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 3.0)
            sink = BridgeSink(bridge)
            seen = await until(lambda: sink.warnings() != [], 3.0)
            assert seen is not None, bridge.stream_report()
            await asyncio.sleep(3.0)  # retries with back-off, no repeated warning
            report = bridge.stream_report()
            warnings = sink.warnings()
    assert warnings == ["autopilot stream DISTANCE_SENSOR not arriving"]
    assert report["DISTANCE_SENSOR"]["state"] == "missing"
    assert report["ATTITUDE"]["state"] == "arriving"
    assert 3 <= report["DISTANCE_SENSOR"]["requests"] <= 6, report  # 0.5, 1, 2 s back-off
    lines = [r.getMessage() for r in caplog.records if "DISTANCE_SENSOR" in r.getMessage()]
    assert len(lines) == 1 and "missing (asked 20 Hz)" in lines[0], lines
    texts = [t for t in fake.statustexts if "DISTANCE_SENSOR" in t]
    assert texts == ["LMC: DISTANCE_SENSOR missing (asked 20 Hz)"], fake.statustexts


async def test_the_status_carries_the_streams(tmp_path: Path) -> None:
    """The whole companion against the strict fake: its status (Zenoh, flight log, monitor,
    dashboard) reports each needed stream arriving and no warning."""
    seen: dict[str, object] = {}

    async def script(flight: Flight) -> None:
        await wait_until(flight, lambda: flight.app is not None
                         and flight.app.status()["autopilot_streams"].get("ATTITUDE", {})
                         .get("state") == "arriving", timeout_s=4.0, what="ATTITUDE arriving")
        await flight.sleep_until(flight.flight_s() + 2.5)
        assert flight.app is not None
        seen.update(flight.app.status())

    await Flight("hover", 6.0, sitl_settings(tmp_path)).run(script)
    streams = seen["autopilot_streams"]
    assert isinstance(streams, dict)
    assert set(streams) == {"ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT",
                            "EKF_STATUS_REPORT"}
    assert all(s["state"] == "arriving" for s in streams.values()), streams
    # no stream warning; "falling behind the camera" (companion/pipeline/keepup.py) says
    # what the machine's load did to the frames, not the streams: not judged here
    warnings = seen["warnings"]
    assert isinstance(warnings, list)
    assert [w for w in warnings if not w.startswith("falling behind")] == [], warnings


async def test_px4s_own_attitude_variance_widens_the_prior() -> None:
    """PX4 states its EKF's attitude variance in ODOMETRY (ArduPilot nowhere): the companion
    asks for it on PX4 only, and a yaw the autopilot says it does not know (15 deg) widens
    the pose solver's prior; a roll/pitch it is surer of than configured (1 deg) does not
    narrow it (companion/sensors.py)."""
    px4 = tuple((s.name, s.rate_hz) for s in needed_streams(15.0, profile="px4"))
    assert ("ODOMETRY", 5.0) in px4 and "ODOMETRY" not in dict(asked())
    cfg = FakeAutopilotConfig(profile="px4", reported_attitude_sigma_deg=(1.0, 15.0))
    async with FakeAutopilot(cfg) as fake, bridge_to(fake, px4) as bridge:
        bridge.report_health("ok")
        history = SensorHistory(bridge, PoseConfig())
        history.start()
        try:
            assert await bridge.wait_link(True, 3.0)
            came = await until(lambda: history.received["ODOMETRY"] >= 2
                               and history.received["ATTITUDE"] >= 2, 3.0)
            assert came is not None, history.received
            newest = history.last_us()
            assert newest is not None
            prior = history.attitude_at(newest)
        finally:
            await history.stop()
    assert prior is not None
    assert math.degrees(prior.yaw_sigma_rad) == pytest.approx(15.0, rel=1e-5)
    assert math.degrees(prior.roll_pitch_sigma_rad) == pytest.approx(
        PoseConfig().attitude_roll_pitch_sigma_deg)
