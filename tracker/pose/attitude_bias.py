"""The autopilot's attitude error, learnt from the fixes and carried between them.

An autopilot's attitude error is not white: it wanders over tens of seconds (gyro bias, a
magnetometer disturbed by the frame; mavlink_bridge/fake_drift.py cites ArduPilot's
figures).  Whenever the landmarks fix the attitude (two or more landmarks, or one large
plate), a fix's attitude is the posterior of the true attitude given the prior and the
pixels; its difference from the autopilot's reported attitude is then a measurement of
that error, good to the fix's own attitude covariance.  :class:`AttitudeBias` keeps that
estimate (per axis: roll, pitch, yaw) and hands the solver the autopilot's attitude
*corrected* by it, with the estimate's 1-sigma grown by a random walk since it was last
measured -- never above the sigma the autopilot's sample states (then the estimate is
forgotten and the raw attitude is used as before).

The loop cannot run away on its own: the corrected attitude is still checked against the
landmarks by the solver (``PoseConfig.check_attitude``), the estimate is only ever set
from a fix's attitude covariance (one small plate hardly narrows it) and floored at
``attitude_bias_floor_*_deg``, since consecutive frames' pixel errors are not independent.
A lone plate's prior is floored at ``attitude_bias_lone_floor_*_deg`` instead (when set):
there the floors' guard against counting the same plates twice hardly applies, and what
counts is how well the estimate is known (docs/decisions.md, "The learnt attitude's floor
for a lone plate").
Pure: no clock of its own; times are the samples' microseconds.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from tracker.pose.config import PoseConfig
from tracker.pose.refine import wrap_angle
from tracker.pose.types import AttitudeSample, PoseFix


class AttitudeBias:
    """See module doc.  ``correct`` before solving a frame, ``learn`` after."""

    def __init__(self, config: PoseConfig) -> None:
        self.walk_rad2_s = np.radians([config.attitude_bias_walk_rp_deg_rt_s,
                                       config.attitude_bias_walk_yaw_deg_rt_s]) ** 2
        self.floor_rad = np.radians([config.attitude_bias_floor_rp_deg,
                                     config.attitude_bias_floor_yaw_deg])
        self.lone_floor_rad = np.radians([
            config.attitude_bias_lone_floor_rp_deg or config.attitude_bias_floor_rp_deg,
            config.attitude_bias_lone_floor_yaw_deg or config.attitude_bias_floor_yaw_deg])
        self.error_rad = np.zeros(3)  # autopilot minus truth, roll pitch yaw
        # the last fix's own attitude variance, unfloored; None: nothing learnt (or forgotten)
        self.var_rad2: np.ndarray | None = None
        self.t_us: int | None = None
        self.learnt = 0

    def _grow(self, sample: AttitudeSample, lone: bool = False) -> np.ndarray | None:
        """The estimate's variance at the sample's time, floored for a fix of several
        plates or (``lone``) of one (None: forgotten, by the several plates' floor)."""
        if self.var_rad2 is None or self.t_us is None:
            return None
        walk = self.walk_rad2_s[[0, 0, 1]] * max(sample.time_us - self.t_us, 0) / 1e6
        var = np.maximum(self.var_rad2, self.floor_rad[[0, 0, 1]] ** 2) + walk
        cap = np.array([sample.roll_pitch_sigma_rad, sample.roll_pitch_sigma_rad,
                        sample.yaw_sigma_rad]) ** 2
        if np.any(var >= cap):
            return None
        return np.maximum(self.var_rad2, self.lone_floor_rad[[0, 0, 1]] ** 2) + walk \
            if lone else var

    def correct(self, sample: AttitudeSample | None, lone: bool = False
                ) -> AttitudeSample | None:
        """``sample`` less the learnt error, with the estimate's sigma (roll/pitch: the
        larger of the two; ``lone``: as a lone plate's prior); unchanged when nothing is
        learnt."""
        if sample is None:
            return None
        var = self._grow(sample, lone)
        if var is None:
            return sample
        r, p, y = np.array([sample.roll_rad, sample.pitch_rad, sample.yaw_rad]) - self.error_rad
        return replace(sample, roll_rad=float(r), pitch_rad=float(p),
                       yaw_rad=math.remainder(float(y), math.tau),
                       roll_pitch_sigma_rad=float(np.sqrt(max(var[0], var[1]))),
                       yaw_sigma_rad=float(np.sqrt(var[2])))

    def learn(self, raw: AttitudeSample | None, fix: object) -> None:
        """After a fix solved with ``correct(raw)`` (or rejecting it): its attitude and
        attitude covariance are the new estimate of the autopilot's error."""
        if raw is None or not isinstance(fix, PoseFix) or fix.attitude_prior == "none":
            return
        cov = np.asarray(fix.covariance)[3:, 3:]
        var = np.diag(cov).copy()
        if not np.all(np.isfinite(var)):
            return
        raw_rpy = np.array([raw.roll_rad, raw.pitch_rad, raw.yaw_rad])
        self.error_rad = wrap_angle(raw_rpy - np.asarray(fix.attitude_rpy_rad))
        self.var_rad2, self.t_us = var, fix.time_us
        self.learnt += 1
