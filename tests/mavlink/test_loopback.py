"""Bridge <-> fake autopilot over UDP loopback: link, heartbeat, telemetry, vision per profile."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import time
from dataclasses import replace

import pytest

from mavlink_bridge.bridge import origin_seen
from mavlink_bridge.link import MAV_AUTOPILOT_INVALID, MAV_TYPE_ONBOARD_CONTROLLER
from mavlink_bridge.messages import LandingTargetFix, Profile, odometry_fields
from mavlink_bridge.telemetry import (
    Attitude,
    DistanceSensor,
    GeoPoint,
    GlobalPosition,
    LocalPositionNed,
    StatusText,
)

from .conftest import stamp_age_errors_ms, stream_fixes, truth_fix, wait_for, wired


async def test_heartbeat_identifies_an_onboard_controller_with_the_autopilots_sysid() -> None:
    """Our HEARTBEAT: ONBOARD_CONTROLLER, AUTOPILOT_INVALID, compid 197, sysid adopted (42)."""
    async with wired({"system_id": 42}) as (ap, bridge):
        assert await wait_for(lambda: any(h.system_id == 42 for h in ap.heartbeats))
        hb = [h for h in ap.heartbeats if h.system_id == 42][-1]
        assert (hb.component_id, hb.type, hb.autopilot) == (197, MAV_TYPE_ONBOARD_CONTROLLER,
                                                            MAV_AUTOPILOT_INVALID)
        assert bridge.link.autopilot_sysid == 42


async def test_heartbeat_status_follows_application_health() -> None:
    """ok -> ACTIVE 4, standby -> STANDBY 3, degraded -> CRITICAL 5, failed -> EMERGENCY 6;
    no report for health_timeout_s -> CRITICAL."""
    async with wired(bridge_kw={"health_timeout_s": 0.5}) as (ap, bridge):
        assert await wait_for(lambda: bool(ap.heartbeats) and ap.heartbeats[-1].system_status == 4)
        bridge.report_health("standby")
        assert await wait_for(lambda: ap.heartbeats[-1].system_status == 3)
        bridge.report_health("degraded")
        assert await wait_for(lambda: ap.heartbeats[-1].system_status == 5)
        bridge.report_health("failed")
        assert await wait_for(lambda: ap.heartbeats[-1].system_status == 6)
        bridge.report_health("ok")
        assert await wait_for(lambda: ap.heartbeats[-1].system_status == 4)
        # stop reporting: the heartbeat must turn critical and say so
        assert await wait_for(lambda: ap.heartbeats[-1].system_status == 5, 2.0)
        assert await wait_for(lambda: "LMC: application not responding" in ap.statustexts)


async def test_telemetry_cache_and_generator_follow_the_vehicle() -> None:
    # the permissive fake streams everything, truth included: this is about the cache
    async with wired({"streams": "all", "judge": "truth"}) as (_ap, bridge):
        assert await wait_for(lambda: all(bridge.latest(n) is not None for n in (
            "ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME",
            "DISTANCE_SENSOR", "EKF_STATUS_REPORT")))
        pos = bridge.latest("LOCAL_POSITION_NED")
        assert pos is not None and isinstance(pos.value, LocalPositionNed)
        assert pos.value.down_m == -5.0  # the default trajectory hovers at 5 m
        rng = bridge.latest("DISTANCE_SENSOR")
        assert rng is not None and isinstance(rng.value, DistanceSensor)
        assert rng.value.distance_m == 5.0
        got = []
        async with contextlib.aclosing(bridge.subscribe("ATTITUDE")) as stream:
            async for item in stream:
                got.append(item)
                if len(got) == 3:
                    break
        assert all(isinstance(i.value, Attitude) for i in got)
        assert got[0].received_ns < got[1].received_ns < got[2].received_ns
        assert bridge.link._hub.subscriber_count("ATTITUDE") == 0  # released in finally


async def test_origin_is_retried_through_failures_until_the_position_shows_it() -> None:
    """ArduPilot SITL answers FAILED while its EKF is not ready; we must keep trying."""
    async with wired({"origin_fail_first": 5, "streams": "all"}) as (ap, bridge):
        assert await wait_for(lambda: bridge.origin_confirmed, 3.0)
        results = [c["result"] for c in ap.commands if c["command"] == 611]
        assert results[:5] == [4] * 5 and 0 in results
        assert ap.origin == (47.39, 8.54, 400.0)
        assert await wait_for(lambda: origin_seen(bridge.latest("GLOBAL_POSITION_INT")))
        gpi = bridge.latest("GLOBAL_POSITION_INT")
        assert gpi is not None and isinstance(gpi.value, GlobalPosition)
        assert abs(gpi.value.lat_deg - 47.39) < 1e-3
        assert await wait_for(lambda: bridge.latest("HOME_POSITION") is not None)
        home = bridge.latest("HOME_POSITION")
        assert home is not None and isinstance(home.value, GeoPoint)
        assert (home.value.lat_deg, home.value.alt_m) == pytest.approx((47.39, 400.0))
        text = bridge.latest("STATUSTEXT")
        assert text is not None and text.value == StatusText(6, "EKF3 IMU0 origin set")
        n_sent = bridge.origin_attempts
        await stream_fixes(ap, bridge, 5)
        assert bridge.origin_attempts == n_sent  # no more once confirmed


async def test_ardupilot_odometry_is_fused_at_the_configured_rate() -> None:
    async with wired() as (ap, bridge):
        results = await stream_fixes(ap, bridge, 30, period_s=0.01, velocity_ned_m_s=(0, 0, 0))
        assert results.count("sent") >= 5 and "rate_limited" in results
        assert await wait_for(lambda: len(ap.vision) == results.count("sent"))
        assert {r.reason for r in ap.vision} == {"fused"}
        assert {(r.frame_id, r.child_frame_id) for r in ap.vision} == {(20, 12)}
        stamps = [r.time_usec for r in ap.vision]
        assert min(b - a for a, b in itertools.pairwise(stamps)) >= 20_000
        assert all(r.innovation_m < 0.5 for r in ap.vision)


async def test_ardupilot_vpe_is_fused() -> None:
    async with wired(bridge_kw={"output": "vpe"}) as (ap, bridge):
        results = await stream_fixes(ap, bridge, 5)
        assert results == ["sent"] * 5
        assert await wait_for(lambda: len(ap.vision) == 5)
        assert {(r.name, r.reason) for r in ap.vision} == {("VISION_POSITION_ESTIMATE", "fused")}


async def test_stale_and_non_finite_fixes_never_leave() -> None:
    async with wired() as (ap, bridge):
        old = truth_fix(ap, time_us=time.monotonic_ns() // 1000 - 500_000)
        assert await bridge.send_fix(old) == "stale"
        nan_pos = truth_fix(ap, position_ned_m=(math.nan, 0, 0))
        inf_att = truth_fix(ap, attitude_rpy_rad=(0, math.inf, 0))
        assert await bridge.send_fix(nan_pos) == "non_finite"
        assert await bridge.send_fix(inf_att) == "non_finite"
        assert await bridge.send_fix(truth_fix(ap)) == "sent"
        assert await wait_for(lambda: len(ap.vision) == 1)
        assert bridge.stats()["vision"] == {"stale": 1, "non_finite": 2, "sent": 1}


async def test_reset_counter_bump_resets_instead_of_gating() -> None:
    """A jump of 20 m is gated out; the same jump with a new reset_counter is a reset."""
    async with wired() as (ap, bridge):
        await stream_fixes(ap, bridge, 3)
        s = ap.truth(ap.flight_s()).position_ned_m
        jumped = (s[0] + 20.0, s[1], s[2])
        assert await bridge.send_fix(truth_fix(ap, position_ned_m=jumped)) == "sent"
        await asyncio.sleep(0.04)
        await stream_fixes(ap, bridge, 1, position_ned_m=jumped, reset_counter=1)
        assert await wait_for(lambda: len(ap.vision) == 5)
        assert [r.reason for r in ap.vision[3:]] == ["innovation_gate", "reset"]


async def test_px4_odometry_local_ned_vision_with_timesync() -> None:
    """PX4: frame LOCAL_NED, estimator VISION; TIMESYNC answered so stamps convert."""
    async with wired({"profile": "px4", "timesync_samples_required": 10},
                     {"profile": "px4"}) as (ap, bridge):
        assert await wait_for(lambda: ap.timesync_synced, 3.0)
        assert bridge.link.counters["timesync_answered"] >= 10
        await stream_fixes(ap, bridge, 5)
        assert await wait_for(lambda: len(ap.vision) == 5)
        assert {(r.frame_id, r.estimator_type, r.reason) for r in ap.vision} == {(1, 2, "fused")}
        # converted stamps carry their true age to half a TIMESYNC round trip, however late
        # the message came (an unconverted stamp is off by the companion's uptime)
        half_rtt_ms = ap.config.timesync_max_rtt_ms / 2
        assert all(abs(e) <= half_rtt_ms for e in stamp_age_errors_ms(ap)), stamp_age_errors_ms(ap)
        # a stamp from another clock (10 s off) is not in the synced time base: rejected
        await asyncio.sleep(0.04)
        wrong = truth_fix(ap)
        bridge.link.send("ODOMETRY", **odometry_fields(
            replace(wrong, time_us=wrong.time_us - 10_000_000), "px4"))
        assert await wait_for(lambda: len(ap.vision) == 6)
        assert ap.vision[-1].reason == "stamp_out_of_range"


async def test_fake_enforces_frames_mocap_and_spacing() -> None:
    """The fake's rules: wrong ODOMETRY frames (ArduPilot), MOCAP (PX4), < 20 ms apart."""
    cases: tuple[tuple[Profile, dict[str, int], str], ...] = (
        ("ardupilot", {"frame_id": 1}, "odometry_frames_not_20_12"),
        ("ardupilot", {"child_frame_id": 8}, "odometry_frames_not_20_12"),
        ("px4", {"estimator_type": 6}, "mocap_not_fused_by_ekf2"),
        ("px4", {"frame_id": 14}, "odometry_frame_unsupported"),
    )
    for profile, fields, reason in cases:
        async with wired({"profile": profile}, {"profile": profile}) as (ap, bridge):
            f = odometry_fields(truth_fix(ap), profile)
            f.update(fields)
            bridge.link.send("ODOMETRY", **f)
            assert await wait_for(lambda: len(ap.vision) == 1)
            assert (ap.vision[0].accepted, ap.vision[0].reason) == (False, reason)
    async with wired() as (ap, bridge):
        a = truth_fix(ap)
        bridge.link.send("ODOMETRY", **odometry_fields(a, "ardupilot"))
        bridge.link.send("ODOMETRY", **odometry_fields(
            truth_fix(ap, time_us=a.time_us + 5_000), "ardupilot"))
        assert await wait_for(lambda: len(ap.vision) == 2)
        assert ap.vision[1].reason == "under_20ms_apart"


async def test_landing_target_frames_per_profile() -> None:
    for profile, frame in (("ardupilot", 12), ("px4", 1)):
        async with wired({"profile": profile}, {"profile": profile}) as (ap, bridge):
            lt = LandingTargetFix(time.monotonic_ns() // 1000, (0.5, -0.2, 4.0), (3.0, 1.0, 0.0))
            assert await bridge.send_landing_target(lt) == "sent"
            assert await wait_for(lambda: len(ap.landing_targets) == 1)
            got = ap.landing_targets[0]
            assert (got["frame"], got["accepted"], got["position_valid"]) == (frame, True, 1)
