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


def fix(t_s: float, own_deg: tuple[float, float, float], prior: str = "used",
        prior_deg: tuple[float, float, float] | None = (2.5, 2.5, 5.0)) -> PoseFix:
    """A fix at the truth's attitude whose landmarks alone fix the attitude to ``own_deg``
    (1-sigma; inf: not at all), solved with a prior of ``prior_deg`` (None: none)."""
    info = np.diag([100.0, 100.0, 100.0, *np.radians(own_deg) ** -2.0])
    if prior_deg is not None:
        info[3:, 3:] += np.diag(np.radians(prior_deg) ** -2.0)
    return PoseFix(round(t_s * 1e6), (0.0, 0.0, -4.0), (0.0, 0.0, RAD(87.0)),
                   np.linalg.inv(info), 80, ("a", "b"), "pnp", attitude_prior=prior)


def deg(sample: AttitudeSample | None) -> tuple[float, float]:
    assert sample is not None
    return math.degrees(sample.roll_pitch_sigma_rad), math.degrees(sample.yaw_sigma_rad)


def test_a_learnt_error_corrects_the_next_samples_and_its_sigma_grows() -> None:
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    assert bias.correct(raw(0.0)) == raw(0.0)  # nothing learnt: unchanged
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6)))
    one = bias.correct(raw(1.0))
    assert one is not None
    assert (one.roll_rad, one.pitch_rad, one.yaw_rad) == pytest.approx((0.0, 0.0, RAD(87.0)))
    # the landmarks' own 0.6 deg (not the posterior's 0.596 with the prior) grown for 1 s
    assert deg(one)[1] == pytest.approx(math.hypot(0.6, 0.4))
    later = bias.correct(raw(20.0))
    assert later is not None and later.yaw_sigma_rad > one.yaw_sigma_rad
    assert bias.correct(raw(400.0)) == raw(400.0)  # grown past the stated sigma: forgotten


def test_only_fixes_that_used_the_attitude_teach_it() -> None:
    """A fix that rejected the prior (the landmarks disagree with it) teaches nothing:
    which of the two is wrong is not known."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.correct(raw(0.0))
    bias.learn(raw(0.0), NoFix(0, "nothing"))
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6), prior="none", prior_deg=None))
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6), prior="rejected", prior_deg=None))
    bias.learn(None, fix(0.0, (0.3, 0.3, 0.6)))
    assert bias.learnt == 0 and bias.correct(raw(0.1)) == raw(0.1)


def test_a_tight_prior_does_not_make_the_estimate_tighter_than_the_landmarks() -> None:
    """Frame after frame the same pixels meet the estimate they made: the posterior shrinks
    as if they were new, the estimate stays at what the landmarks fix alone."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.correct(raw(0.0))
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6)))
    for i in range(1, 60):
        t = i / 30
        given = deg(bias.correct(raw(t)))
        bias.learn(raw(t), fix(t, (0.3, 0.3, 0.6), prior_deg=(given[0], given[0], given[1])))
    rp, yaw = deg(bias.correct(raw(2.0)))
    assert rp == pytest.approx(math.hypot(0.3, 0.3 / math.sqrt(30)), rel=1e-3)  # not 0.15
    assert yaw == pytest.approx(math.hypot(0.6, 0.4 / math.sqrt(30)), rel=1e-3)


def test_an_axis_the_landmarks_do_not_fix_keeps_its_estimate() -> None:
    """A view that fixes roll and pitch but its yaw worse than the estimate knows it: the
    yaw learnt before is kept (and grows), the roll and pitch are learnt anew; a view that
    does not fix the pose at all (one plate's tilt against its distance) teaches nothing."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.correct(raw(0.0))
    bias.learn(raw(0.0), fix(0.0, (0.3, 0.3, 0.6)))
    given = deg(bias.correct(raw(1.0, yaw_deg=91.0)))
    bias.learn(raw(1.0, yaw_deg=91.0), fix(1.0, (0.2, 0.2, 5.0),
                                           prior_deg=(given[0], given[0], given[1])))
    got = bias.correct(raw(1.0, yaw_deg=91.0))
    assert got is not None
    assert math.degrees(got.yaw_rad) == pytest.approx(88.0)  # 91 less the 3 deg learnt before
    assert deg(got) == pytest.approx((0.2, math.hypot(0.6, 0.4)))
    singular = np.diag([1.0, 1.0, 1.0, 1.0, 1.0, 1e12])  # the prior's information only
    bias.given_var = np.full(3, 1e-12)
    assert np.all(bias.landmarks_only(singular) == math.inf)


def test_the_sigma_is_floored() -> None:
    """A fix whose landmarks claim 0.01 deg is not believed below the last guard."""
    bias = AttitudeBias(PoseConfig(learn_attitude_bias=True))
    bias.correct(raw(0.0))
    bias.learn(raw(0.0), fix(0.0, (0.01, 0.01, 0.01)))
    assert deg(bias.correct(raw(0.0))) == pytest.approx((0.15, 0.05))
