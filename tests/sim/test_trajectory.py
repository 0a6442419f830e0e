"""Scripted trajectories: timing, velocity, heading, loop, tilt."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.sim.trajectory import Trajectory, TrajectoryConfig, Waypoint


def path() -> Trajectory:
    return Trajectory(TrajectoryConfig(waypoints=(
        Waypoint((0.0, 0.0, -5.0), yaw_deg=0.0, hold_s=1.0),
        Waypoint((10.0, 0.0, -5.0), speed_m_s=2.0, yaw_deg=90.0, hold_s=2.0),
        Waypoint((10.0, 6.0, -5.0), speed_m_s=3.0, yaw_deg=-170.0, yaw_rate_deg_s=90.0),
    )))


def test_legs_take_distance_over_speed_plus_holds() -> None:
    t = path()
    assert t.duration_s == pytest.approx(1.0 + 5.0 + 2.0 + 2.0)
    assert t.state_at(0.5).position_ned_m == (0.0, 0.0, -5.0)
    assert t.state_at(3.5).position_ned_m == pytest.approx((5.0, 0.0, -5.0))
    assert t.state_at(7.0).position_ned_m == pytest.approx((10.0, 0.0, -5.0))
    assert t.state_at(99.0).position_ned_m == pytest.approx((10.0, 6.0, -5.0))


def test_velocity_is_the_derivative_of_position() -> None:
    t = path()
    for ts in (2.0, 4.3, 8.5):
        a, b = t.state_at(ts - 1e-3), t.state_at(ts + 1e-3)
        fd = (np.subtract(b.position_ned_m, a.position_ned_m)) / 2e-3
        assert np.allclose(fd, t.state_at(ts).velocity_ned_m_s, atol=1e-6)
    assert t.state_at(6.5).velocity_ned_m_s == (0.0, 0.0, 0.0)  # holding


def test_heading_turns_the_short_way() -> None:
    t = path()
    assert t.state_at(3.5).attitude_rpy_rad[2] == pytest.approx(math.radians(45.0))
    # 90 -> -170 is +100 degrees the short way (through 180)
    assert t.state_at(9.0).attitude_rpy_rad[2] == pytest.approx(math.radians(140.0))
    assert t.state_at(9.0).body_rates_rad_s[2] > 0


def test_turn_on_the_spot_uses_yaw_rate() -> None:
    t = Trajectory(TrajectoryConfig(waypoints=(
        Waypoint((0.0, 0.0, -5.0), yaw_deg=0.0),
        Waypoint((0.0, 0.0, -5.0), yaw_deg=90.0, yaw_rate_deg_s=30.0),
    )))
    assert t.duration_s == pytest.approx(3.0)
    assert t.state_at(1.5).attitude_rpy_rad[2] == pytest.approx(math.radians(45.0))


def test_loop_returns_to_the_start() -> None:
    t = Trajectory(TrajectoryConfig(loop=True, waypoints=(
        Waypoint((0.0, 0.0, -5.0)), Waypoint((4.0, 0.0, -5.0), speed_m_s=2.0))))
    assert t.duration_s == pytest.approx(4.0)
    assert t.state_at(3.0).position_ned_m == pytest.approx((2.0, 0.0, -5.0))
    assert t.state_at(5.0).position_ned_m == pytest.approx((2.0, 0.0, -5.0))


def test_tilt_noses_down_when_flying_forward() -> None:
    t = Trajectory(TrajectoryConfig(tilt_deg_per_m_s=3.0, waypoints=(
        Waypoint((0.0, 0.0, -5.0)), Waypoint((10.0, 0.0, -5.0), speed_m_s=2.0))))
    roll, pitch, _ = t.state_at(1.0).attitude_rpy_rad
    assert pitch == pytest.approx(-math.radians(6.0)) and roll == pytest.approx(0.0)


def test_sway_moves_a_hover_consistently() -> None:
    t = Trajectory(TrajectoryConfig(sway_m=0.5, sway_period_s=4.0,
                                    waypoints=(Waypoint((1.0, 2.0, -3.0), hold_s=100.0),)))
    s = t.state_at(1.0)
    assert s.position_ned_m == pytest.approx((1.5, 2.5, -3.0))
    a, b = t.state_at(1.0 - 1e-4), t.state_at(1.0 + 1e-4)
    fd = np.subtract(b.position_ned_m, a.position_ned_m) / 2e-4
    assert np.allclose(fd, s.velocity_ned_m_s, atol=1e-4)
