"""Closed loop: fixes' attitude fed back as the next prior (tracker.pose.attitude_loop).

A crude model of the EKF coupling of issue 19 (the autopilot's attitude made of our fixes,
its error growing with the fixes' position error): the prior as the code had it (0.2 deg
roll/pitch, 1 deg yaw, trusted) runs away; the honest prior, checked against the
landmarks, does not.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tracker.pose.attitude_loop import LoopConfig, LoopStep, fly_loop
from tracker.pose.scenarios import NEES_HIGH_3DOF, NEES_LOW_3DOF, scenarios

WALL = replace(next(s for s in scenarios() if s.name == "hover_wall_attitude"), duration_s=60.0)
TODAY = LoopConfig(prior_sigma_deg=(0.2, 1.0), check=False)  # before issue 19


def _errors(steps: list[LoopStep]) -> list[float]:
    return [s.position_error_m for s in steps if s.position_error_m is not None]


def test_the_honest_checked_prior_does_not_run_away() -> None:
    steps = fly_loop(WALL, LoopConfig(), seed=1)  # 5 deg initial yaw error, 2 deg/min drift
    errors = _errors(steps)
    assert len(errors) == len(steps)  # a fix every frame
    assert max(s.attitude_error_deg for s in steps[100:]) < 3.0
    assert max(errors) < 1.0
    nees = [s.nees for s in steps if s.nees is not None]
    inside = np.mean([NEES_LOW_3DOF <= n <= NEES_HIGH_3DOF for n in nees])
    assert inside >= 0.9


def test_the_trusted_tight_prior_runs_away() -> None:
    steps = fly_loop(WALL, TODAY, seed=1)
    assert max(s.attitude_error_deg for s in steps) > 10.0
    late = steps[len(steps) // 2:]
    # the fixes follow the attitude away until the landmarks no longer fit at all
    lost = sum(s.position_error_m is None for s in late) / len(late)
    assert lost > 0.5 or max(_errors(late)) > 2.0
