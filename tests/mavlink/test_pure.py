"""Pure parts: endpoint strings, field builders, the output gate."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from mavlink_bridge.endpoint import parse_endpoint
from mavlink_bridge.errors import EndpointError
from mavlink_bridge.messages import (
    LandingTargetFix,
    VisionFix,
    euler_to_quaternion,
    fix_problem,
    landing_target_fields,
    ned_to_body,
    odometry_fields,
    upper_triangle,
    vpe_fields,
)
from mavlink_bridge.output import OutputGate

COV = tuple(0.04 if k in (0, 6, 11) else 0.0 for k in range(21))


def fix(t_us: int = 1_000_000, **kw: object) -> VisionFix:
    base = dict(time_us=t_us, position_ned_m=(1.0, 2.0, -3.0), attitude_rpy_rad=(0.0, 0.0, 0.5),
                covariance=COV, quality_percent=80, reset_counter=3)
    base.update(kw)
    return VisionFix(**base)  # type: ignore[arg-type]


@pytest.mark.parametrize("spec,kind,where,num", [
    ("udpin:0.0.0.0:14550", "udpin", "0.0.0.0", 14550),
    ("udpout:127.0.0.1:14551", "udpout", "127.0.0.1", 14551),
    ("tcp:localhost:5760", "tcp", "localhost", 5760),
    ("tcpin:127.0.0.1:0", "tcpin", "127.0.0.1", 0),
    ("serial:/dev/ttyAMA0:921600", "serial", "/dev/ttyAMA0", 921600),
])
def test_endpoint_strings_parse(spec: str, kind: str, where: str, num: int) -> None:
    ep = parse_endpoint(spec)
    assert ep.kind == kind
    got = (ep.device, ep.baud) if kind == "serial" else (ep.host, ep.port)
    assert got == (where, num)
    assert str(ep) == spec


@pytest.mark.parametrize("spec", ["garbage:1.2.3.4:5", "tcp:host", "udpin:host:99999",
                                  "serial:/dev/x:0", "14550", "tcpin::x"])
def test_bad_endpoint_strings_are_refused_with_the_string(spec: str) -> None:
    with pytest.raises(EndpointError, match="endpoint"):
        parse_endpoint(spec)


def test_upper_triangle_of_a_6x6_matrix_is_row_major() -> None:
    m = np.arange(36, dtype=float).reshape(6, 6)
    m = (m + m.T) / 2
    tri = upper_triangle(m)
    assert len(tri) == 21
    assert tri[:6] == list(m[0])
    assert tri[6] == m[1, 1] and tri[11] == m[2, 2] and tri[20] == m[5, 5]


def test_quaternion_of_yaw_90_rotates_body_x_to_east() -> None:
    w, x, y, z = euler_to_quaternion(0.0, 0.0, math.pi / 2)
    assert (w, x, y, z) == pytest.approx((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))
    # v_body for an eastward velocity, facing east: straight ahead
    assert ned_to_body((0.0, 1.0, 0.0), 0.0, 0.0, math.pi / 2) == pytest.approx([1.0, 0.0, 0.0])


def test_ardupilot_odometry_uses_frames_20_and_12_exactly() -> None:
    f = odometry_fields(fix(), "ardupilot")
    assert (f["frame_id"], f["child_frame_id"]) == (20, 12)
    assert f["quality"] == 80 and f["reset_counter"] == 3
    assert all(math.isfinite(v) for v in (f["vx"], f["vy"], f["vz"]))


def test_px4_odometry_is_local_ned_vision_and_marks_unknown_velocity() -> None:
    f = odometry_fields(fix(), "px4")
    assert (f["frame_id"], f["child_frame_id"], f["estimator_type"]) == (1, 12, 2)
    assert math.isnan(f["vx"]) and math.isnan(f["velocity_covariance"][0])
    g = odometry_fields(fix(velocity_ned_m_s=(1.0, 0.0, 0.0)), "px4")
    assert all(math.isfinite(v) for v in (g["vx"], g["vy"], g["vz"]))


def test_vpe_fields_carry_pose_covariance_and_reset_counter() -> None:
    f = vpe_fields(fix())
    assert (f["x"], f["y"], f["z"], f["yaw"]) == (1.0, 2.0, -3.0, 0.5)
    assert f["covariance"] == list(COV) and f["reset_counter"] == 3


@pytest.mark.parametrize("kw,reason", [
    ({"position_ned_m": (math.nan, 0.0, 0.0)}, "non_finite"),
    ({"attitude_rpy_rad": (0.0, math.inf, 0.0)}, "non_finite"),
    ({"covariance": (math.nan,) * 21}, "bad_covariance"),
    ({"covariance": (1.0,) * 20}, "bad_covariance"),
    ({"quality_percent": 101}, "bad_quality"),
])
def test_bad_fixes_are_named(kw: dict[str, Any], reason: str) -> None:
    assert fix_problem(fix(**kw), 1_000_000, 200_000) == reason


def test_stale_and_future_fixes_are_named() -> None:
    assert fix_problem(fix(1_000_000), 1_300_000, 200_000) == "stale"
    assert fix_problem(fix(1_000_000), 500_000, 200_000) == "future"
    assert fix_problem(fix(1_000_000), 1_100_000, 200_000) is None


def test_landing_target_per_profile() -> None:
    lt = LandingTargetFix(1, offset_body_frd_m=(1.0, 2.0, 10.0), position_ned_m=(5.0, 6.0, 0.0))
    ap = landing_target_fields(lt, "ardupilot")
    px = landing_target_fields(lt, "px4")
    assert ap is not None and px is not None
    assert ap["frame"] == 12 and (ap["x"], ap["y"], ap["z"]) == (1.0, 2.0, 10.0)
    assert ap["angle_x"] == pytest.approx(math.atan2(2.0, 10.0))
    assert ap["angle_y"] == pytest.approx(-math.atan2(1.0, 10.0))
    assert ap["distance"] == pytest.approx(math.sqrt(105.0))
    assert px["frame"] == 1 and (px["x"], px["y"], px["z"]) == (5.0, 6.0, 0.0)
    assert px["position_valid"] == 1
    zero = LandingTargetFix(1, offset_body_frd_m=(0.0, 0.0, 0.0), position_ned_m=(0.0, 0.0, 0.0))
    assert landing_target_fields(zero, "ardupilot") is None


def test_gate_keeps_samples_20ms_apart_and_at_rate() -> None:
    """The rate is the samples' (their stamps are what the autopilot spaces and fuses):
    a fix of the next 30 Hz frame goes out however soon after the last send it is ready."""
    gate = OutputGate(rate_hz=30.0, max_age_us=200_000)
    t0_ns = 10**12
    f0 = fix(t0_ns // 1000)
    assert gate.check_fix(f0, t0_ns) is None
    gate.commit(f0.time_us)
    # 10 ms later in sample time: too close for EKF3
    f1 = fix(f0.time_us + 10_000)
    assert gate.check_fix(f1, t0_ns + 40_000_000) == "rate_limited"
    # 25 ms later in sample time: over the 30 Hz rate, however late it is sent
    f2 = fix(f0.time_us + 25_000)
    assert gate.check_fix(f2, t0_ns + 40_000_000) == "rate_limited"
    # the next frame (33 ms), ready only 5 ms after the last send (the last frame was slow)
    f3 = fix(f0.time_us + 33_333)
    assert gate.check_fix(f3, t0_ns + 38_333_000) is None
    assert gate.check_fix(fix(f0.time_us), t0_ns + 40_000_000) == "not_newer"
    # at 50 Hz the EKF's 20 ms is the bound
    fast = OutputGate(rate_hz=50.0, max_age_us=200_000)
    fast.commit(f0.time_us)
    assert fast.check_fix(fix(f0.time_us + 19_000), t0_ns + 19_000_000) == "rate_limited"
    assert fast.check_fix(fix(f0.time_us + 20_000), t0_ns + 20_000_000) is None
