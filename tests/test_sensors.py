"""SensorHistory: the autopilot's attitude, height and range at a frame's capture time."""

from __future__ import annotations

import math
from typing import Any

import pytest

from companion.sensors import SensorHistory
from mavlink_bridge.telemetry import Attitude, DistanceSensor, LocalPositionNed, Odometry, convert
from tracker.pose.config import PoseConfig


def _history(**config: Any) -> SensorHistory:
    return SensorHistory(bridge=None, config=PoseConfig(**config))  # type: ignore[arg-type]


def _att(roll: float, pitch: float, yaw: float) -> Attitude:
    return Attitude(0, roll, pitch, yaw, 0.0, 0.0, 0.0)


def _down(d: float) -> LocalPositionNed:
    return LocalPositionNed(0, 1.0, 2.0, d, 0.0, 0.0, 0.0)


def _range(d: float, orientation: int = 25) -> DistanceSensor:
    return DistanceSensor(0, d, 0.2, 40.0, orientation, 0)


def test_attitude_is_interpolated_at_the_frame_time_with_the_configured_sigmas() -> None:
    h = _history(attitude_roll_pitch_sigma_deg=3.0, attitude_yaw_sigma_deg=6.0)
    h.add("ATTITUDE", 1_000_000, _att(0.0, 0.1, math.radians(179.0)))
    h.add("ATTITUDE", 1_050_000, _att(0.02, 0.2, math.radians(-179.0)))
    a = h.attitude_at(1_025_000)
    assert a is not None and a.time_us == 1_025_000
    assert a.roll_rad == pytest.approx(0.01) and a.pitch_rad == pytest.approx(0.15)
    assert abs(math.remainder(a.yaw_rad - math.pi, math.tau)) < 1e-9  # the short way round
    assert a.roll_pitch_sigma_rad == pytest.approx(math.radians(3.0))
    assert a.yaw_sigma_rad == pytest.approx(math.radians(6.0))


def test_no_sample_near_the_frame_gives_none() -> None:
    h = _history()
    assert h.attitude_at(1_000_000) is None
    h.add("ATTITUDE", 1_000_000, _att(0.0, 0.0, 0.0))
    assert h.attitude_at(1_050_000) is not None
    assert h.attitude_at(1_200_000) is None  # 0.2 s after the last: max_sample_age_s 0.1
    h.add("ATTITUDE", 1_500_000, _att(0.0, 0.0, 0.0))
    assert h.attitude_at(1_250_000) is None  # inside a hole of the stream


def test_height_from_local_position_down_unless_turned_off() -> None:
    h = _history(altitude_sigma_m=0.7)
    h.add("LOCAL_POSITION_NED", 1_000_000, _down(-10.0))
    h.add("LOCAL_POSITION_NED", 1_100_000, _down(-11.0))
    alt = h.altitude_at(1_050_000)
    assert alt is not None and alt.down_m == pytest.approx(-10.5) and alt.sigma_m == 0.7
    off = _history(use_altitude=False)
    off.add("LOCAL_POSITION_NED", 1_000_000, _down(-10.0))
    assert off.altitude_at(1_000_000) is None


def test_range_only_when_configured_nearest_sample_within_limits() -> None:
    h = _history(rangefinder=True, rangefinder_sigma_m=0.04)
    h.add("DISTANCE_SENSOR", 1_000_000, _range(5.0))
    h.add("DISTANCE_SENSOR", 1_100_000, _range(9.0))
    r = h.range_at(1_040_000)
    assert r is not None and r.distance_m == 5.0 and r.axis_body == (0.0, 0.0, 1.0)
    assert r.sigma_m == 0.04
    h.add("DISTANCE_SENSOR", 1_200_000, _range(45.0))  # beyond its max_distance
    assert h.range_at(1_200_000) is None
    h.add("DISTANCE_SENSOR", 1_300_000, _range(3.0, orientation=0))  # forward
    fwd = h.range_at(1_300_000)
    assert fwd is not None and fwd.axis_body == (1.0, 0.0, 0.0)
    off = _history()
    off.add("DISTANCE_SENSOR", 1_000_000, _range(5.0))
    assert off.range_at(1_000_000) is None


def test_call_gives_all_three() -> None:
    h = _history(rangefinder=True)
    h.add("ATTITUDE", 1_000_000, _att(0.0, 0.0, 0.0))
    h.add("LOCAL_POSITION_NED", 1_000_000, _down(-3.0))
    h.add("DISTANCE_SENSOR", 1_000_000, _range(3.0))
    side = h(1_000_000)
    assert side.attitude is not None and side.altitude is not None and side.laser is not None
    assert h.received == {"ATTITUDE": 1, "LOCAL_POSITION_NED": 1, "DISTANCE_SENSOR": 1,
                          "ODOMETRY": 0}


def test_the_autopilots_own_attitude_variance_only_ever_widens_the_prior() -> None:
    """PX4's ODOMETRY carries its EKF's orientation variance (pose_covariance 15 / 18 / 20):
    a yaw it says it does not know widens the prior; a variance tighter than the configured
    sigma, an old one or NaN (not reported) leaves the configured sigma."""
    cov = [math.nan] * 21
    cov[15], cov[18], cov[20] = math.radians(0.5) ** 2, math.radians(4.0) ** 2, \
        math.radians(20.0) ** 2
    odom = convert("ODOMETRY", {"time_usec": 2_000_000, "pose_covariance": cov})
    assert isinstance(odom, Odometry) and odom.time_boot_ms == 2000
    h = _history(attitude_roll_pitch_sigma_deg=2.5, attitude_yaw_sigma_deg=5.0)
    h.add("ATTITUDE", 1_000_000, _att(0.0, 0.0, 0.0))
    h.add("ODOMETRY", 1_000_000, odom)
    a = h.attitude_at(1_000_000)
    assert a is not None
    assert math.degrees(a.roll_pitch_sigma_rad) == pytest.approx(4.0)  # pitch's, the wider
    assert math.degrees(a.yaw_sigma_rad) == pytest.approx(20.0)
    h.add("ATTITUDE", 2_480_000, _att(0.0, 0.0, 0.0))
    h.add("ATTITUDE", 2_500_000, _att(0.0, 0.0, 0.0))
    late = h.attitude_at(2_500_000)  # the variance 1.5 s old: not counted
    assert late is not None and math.degrees(late.yaw_sigma_rad) == pytest.approx(5.0)
    tight = _history(attitude_roll_pitch_sigma_deg=2.5, attitude_yaw_sigma_deg=5.0)
    tight.add("ATTITUDE", 1_000_000, _att(0.0, 0.0, 0.0))
    tight.add("ODOMETRY", 1_000_000, Odometry(1_000_000, (1e-6, math.nan, 1e-6)))
    a = tight.attitude_at(1_000_000)
    assert a is not None and math.degrees(a.roll_pitch_sigma_rad) == pytest.approx(2.5)
    assert math.degrees(a.yaw_sigma_rad) == pytest.approx(5.0)
    unreported = convert("ODOMETRY", {"time_usec": 0}).attitude_variance_rad2  # no covariance
    assert all(math.isnan(x) for x in unreported), unreported
