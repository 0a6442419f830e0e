"""A crude closed loop of the autopilot's attitude and our fixes (issue 19's runaway).

The autopilot's EKF fuses our fixes, and its attitude -- our prior -- is partly made of
them: with ExtNav as its yaw source it takes our yaw, and position fixes that disagree
with its inertial prediction tilt its roll and pitch.  :func:`fly_loop` models this as
simply as possible: the autopilot's attitude error ``e`` (truth + ``e`` is our prior)
drifts between frames (``yaw_drift_deg_min`` plus a random walk) and, at every fix, moves
``feedback`` of the way to the fix's own attitude error, then grows, in its own direction,
by ``position_feedback`` times the angle that the fix's position error subtends at the
landmarks: the EKF, fed a fix that is off because its attitude was off, takes the offset as
motion that its attitude then explains (positive feedback, the mechanism issue 19 saw:
6-29 deg within seconds).  A fix that follows its prior keeps the error, is off by it, and
the error grows (a runaway); a fix that follows the landmarks is not off and pulls the
prior back.  Pure and deterministic for a seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from tracker.pose.config import PoseConfig
from tracker.pose.refine import wrap_angle
from tracker.pose.scenarios import Scenario, solve_frame, solver_config
from tracker.pose.simulate import simulate_frame
from tracker.pose.types import AttitudeSample, PoseFix


@dataclass(frozen=True)
class LoopConfig:
    """The prior the solver is told, and how the autopilot's attitude error evolves."""

    #: 1-sigma stated with the autopilot's attitude (roll/pitch, yaw), degrees
    prior_sigma_deg: tuple[float, float] = (2.5, 5.0)
    #: the solver checks the prior against the landmarks (off: the code before issue 19)
    check: bool = True
    #: the autopilot's attitude error at the start (roll, pitch, yaw), degrees
    initial_error_deg: tuple[float, float, float] = (0.0, 0.0, 5.0)
    yaw_drift_deg_min: float = 2.0
    #: random walk of each axis, degrees per sqrt(second)
    walk_deg_sqrt_s: float = 0.02
    #: share of the way the autopilot's attitude moves to a fix's attitude
    feedback: float = 1.0
    #: growth of the autopilot's attitude error per fix, times the angle (rad) the fix's
    #: position error subtends at the landmarks it used
    position_feedback: float = 0.5


@dataclass(frozen=True)
class LoopStep:
    """One frame: time, the autopilot's attitude error (deg, largest axis) and, when there
    was a fix, its position error (m) and NEES."""

    t_s: float
    attitude_error_deg: float
    position_error_m: float | None
    nees: float | None
    prior: str  # the fix's attitude_prior, or "" without a fix


def fly_loop(scenario: Scenario, loop: LoopConfig, seed: int = 0) -> list[LoopStep]:
    """Fly ``scenario`` (which must use the attitude) with the attitude loop closed."""
    rng = np.random.default_rng(seed)
    cfg = replace(solver_config(scenario, PoseConfig()), check_attitude=loop.check)
    sig_rp, sig_yaw = (math.radians(v) for v in loop.prior_sigma_deg)
    err = np.radians(np.asarray(loop.initial_error_deg, dtype=np.float64))
    dt = 1.0 / scenario.rate_hz
    walk = math.radians(loop.walk_deg_sqrt_s) * math.sqrt(dt)
    drift = np.array([0.0, 0.0, math.radians(loop.yaw_drift_deg_min) / 60.0 * dt])
    by_id = {lm.landmark_id: lm for lm in scenario.landmarks}
    steps: list[LoopStep] = []
    for k in range(int(scenario.duration_s * scenario.rate_hz)):
        t = k * dt
        frame = simulate_frame(scenario.landmarks, scenario.camera, scenario.trajectory, t, rng,
                               scenario.noise, scenario.laser_axis_body)
        truth = np.asarray(frame.true_attitude_rpy_rad)
        rpy = wrap_angle(truth + err)
        att = AttitudeSample(frame.time_us, float(rpy[0]), float(rpy[1]), float(rpy[2]),
                             sig_rp, sig_yaw)
        fix = solve_frame(scenario, replace(frame, attitude=att), cfg)
        pos_err = nees = None
        prior = ""
        if isinstance(fix, PoseFix):
            e = np.asarray(fix.position_ned_m) - frame.true_position_ned_m
            pos_err = float(np.linalg.norm(e))
            nees = float(e @ np.linalg.solve(fix.covariance[:3, :3], e))
            prior = fix.attitude_prior
            fix_err = wrap_angle(np.asarray(fix.attitude_rpy_rad) - truth)
            err = err + loop.feedback * wrap_angle(fix_err - err)
            used = np.array([by_id[i].position_ned_m for i in fix.landmark_ids])
            dist = float(np.mean(np.linalg.norm(used - frame.true_position_ned_m, axis=1)))
            size = float(np.linalg.norm(err))
            if size > 0.0:
                err = err * (1.0 + loop.position_feedback * pos_err / max(dist, 1e-9) / size)
        steps.append(LoopStep(t, float(np.degrees(np.max(np.abs(err)))), pos_err, nees, prior))
        err = err + drift + rng.normal(0.0, walk, 3)
    return steps
