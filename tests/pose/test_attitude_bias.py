"""Learning the autopilot's attitude error from fixes (tracker/pose/attitude_bias.py)."""

from __future__ import annotations

import math

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
