"""Learning the autopilot's attitude error from fixes (tracker/pose/attitude_bias.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from tracker.pose.attitude_bias import AttitudeBias
from tracker.pose.config import PoseConfig
from tracker.pose.types import AttitudeSample, NoFix, PoseFix

RAD = math.radians


def raw(t_s: float, yaw_deg: float = 90.0) -> AttitudeSample:
    """The autopilot's attitude: the truth (0, 0, 87 deg) off by (+1, -1, +3) deg."""
    return AttitudeSample(round(t_s * 1e6), RAD(1.0), RAD(-1.0), RAD(yaw_deg), RAD(2.5), RAD(5.0))


def fix(t_s: float, sigma_deg: tuple[float, float, float], prior: str = "used") -> PoseFix:
    cov = np.diag([0.01, 0.01, 0.01, *np.radians(sigma_deg) ** 2])
    return PoseFix(round(t_s * 1e6), (0.0, 0.0, -4.0), (0.0, 0.0, RAD(87.0)), cov, 80,
                   ("a", "b"), "pnp", attitude_prior=prior)


def test_a_learnt_error_corrects_the_next_samples_and_its_sigma_grows() -> None:
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    assert bias.correct(raw(0.0)) == raw(0.0)  # nothing learnt: unchanged
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6)))
    one = bias.correct(raw(1.0))
    assert one is not None
    assert (one.roll_rad, one.pitch_rad, one.yaw_rad) == pytest.approx((0.0, 0.0, RAD(87.0)))
    assert math.degrees(one.yaw_sigma_rad) == pytest.approx(math.hypot(0.6, 0.4))
    later = bias.correct(raw(20.0))
    assert later is not None and later.yaw_sigma_rad > one.yaw_sigma_rad
    assert bias.correct(raw(400.0)) == raw(400.0)  # grown past the stated sigma: forgotten


def test_only_fixes_that_used_or_checked_the_attitude_teach_it() -> None:
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.learn(raw(0.0), NoFix(0, "nothing"))
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6), prior="none"))
    bias.learn(None, fix(0.0, (0.3, 0.3, 0.6)))
    assert bias.learnt == 0 and bias.correct(raw(0.1)) == raw(0.1)


def test_the_sigma_is_floored() -> None:
    """A fix claiming 0.01 deg is not believed below the floor (correlated pixel errors)."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.learn(raw(0.0), fix(0.0, (0.01, 0.01, 0.01)))
    got = bias.correct(raw(0.0))
    assert got is not None
    assert math.degrees(got.roll_pitch_sigma_rad) == pytest.approx(0.2)
    assert math.degrees(got.yaw_sigma_rad) == pytest.approx(0.5)


def test_a_lone_plate_takes_the_lone_floors() -> None:
    """A lone plate's prior is floored at ``attitude_bias_lone_floor_*``; a fix of several
    plates keeps the floors, and the estimate is forgotten when theirs would be."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True, attitude_bias_lone_floor_rp_deg=0.1,
                                   attitude_bias_lone_floor_yaw_deg=0.2))
    bias.learn(raw(0.0), fix(0.0, (0.01, 0.01, 0.01)))
    several, lone = bias.correct(raw(0.0)), bias.correct(raw(0.0), lone=True)
    assert several is not None and lone is not None
    assert (math.degrees(several.roll_pitch_sigma_rad), math.degrees(several.yaw_sigma_rad)) \
        == pytest.approx((0.2, 0.5))
    assert (math.degrees(lone.roll_pitch_sigma_rad), math.degrees(lone.yaw_sigma_rad)) \
        == pytest.approx((0.1, 0.2))
    assert (lone.roll_rad, lone.yaw_rad) == (several.roll_rad, several.yaw_rad)
    bias.learn(raw(0.0), fix(0.0, (0.15, 0.15, 0.3)))  # a fix's own sigma over them holds
    lone = bias.correct(raw(0.0), lone=True)
    assert lone is not None
    assert (math.degrees(lone.roll_pitch_sigma_rad), math.degrees(lone.yaw_sigma_rad)) \
        == pytest.approx((0.15, 0.3))
    # forgotten by the several plates' floors: from 0.2 deg, a walk of 0.3 deg/sqrt(s)
    # reaches a sample's stated 0.3 deg after (0.3^2 - 0.2^2) / 0.3^2 = 0.56 s (from 0.15:
    # 0.75 s)
    tight = AttitudeSample(700_000, RAD(1.0), RAD(-1.0), RAD(90.0), RAD(0.3), RAD(5.0))
    assert bias.correct(tight, lone=True) == tight
    assert bias.correct(replace(tight, time_us=500_000), lone=True) != \
        replace(tight, time_us=500_000)


def test_without_lone_floors_a_lone_plate_takes_the_floors() -> None:
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.learn(raw(0.0), fix(0.0, (0.01, 0.01, 0.01)))
    assert bias.correct(raw(1.0), lone=True) == bias.correct(raw(1.0))
