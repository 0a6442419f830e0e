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
landmarks by the solver (``PoseConfig.check_attitude``), and the estimate is only ever set,
axis by axis, from what the fix's landmarks fix *without* the prior: its variance is at least
the landmarks' own (:meth:`AttitudeBias.landmarks_only`), since consecutive frames' pixel
errors are not independent (a long stare at the same plates is one measurement, not many),
and an axis they fix no better than the estimate already knows keeps it (one small plate's
tilt). ``attitude_bias_floor_*_deg`` is only a last guard under that.
Pure: no clock of its own; times are the samples' microseconds.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from tracker.pose.config import PoseConfig
from tracker.pose.refine import wrap_angle
from tracker.pose.types import AttitudeSample, PoseFix

#: Information (eigenvalue) below this share of the largest: that direction is not fixed.
_MIN_INFO_RATIO = 1e-9


class AttitudeBias:
    """See module doc.  ``correct`` before solving a frame, ``learn`` after."""

    def __init__(self, config: PoseConfig) -> None:
        self.walk_rad2_s = np.radians([config.attitude_bias_walk_rp_deg_rt_s,
                                       config.attitude_bias_walk_yaw_deg_rt_s]) ** 2
        self.floor_rad = np.radians([config.attitude_bias_floor_rp_deg,
                                     config.attitude_bias_floor_yaw_deg])
        self.error_rad = np.zeros(3)  # autopilot minus truth, roll pitch yaw
        self.var_rad2: np.ndarray | None = None  # None: nothing learnt (or forgotten)
        self.t_us: int | None = None
        self.learnt = 0
        #: the attitude variances the last corrected sample stated (roll, pitch, yaw)
        self.given_var: np.ndarray | None = None

    def _grow(self, sample: AttitudeSample) -> np.ndarray | None:
        """The estimate's variance at the sample's time (None: forgotten)."""
        if self.var_rad2 is None or self.t_us is None:
            return None
        dt = max(sample.time_us - self.t_us, 0) / 1e6
        var = self.var_rad2 + self.walk_rad2_s[[0, 0, 1]] * dt
        cap = np.array([sample.roll_pitch_sigma_rad, sample.roll_pitch_sigma_rad,
                        sample.yaw_sigma_rad]) ** 2
        return None if np.any(var >= cap) else var

    def correct(self, sample: AttitudeSample | None) -> AttitudeSample | None:
        """``sample`` less the learnt error, with the estimate's sigma (roll/pitch: the
        larger of the two); unchanged when nothing is learnt."""
        if sample is None:
            return None
        var = self._grow(sample)
        if var is None:
            self.given_var = np.array([sample.roll_pitch_sigma_rad, sample.roll_pitch_sigma_rad,
                                       sample.yaw_sigma_rad]) ** 2
            return sample
        rp_var = max(var[0], var[1])
        self.given_var = np.array([rp_var, rp_var, var[2]])
        r, p, y = np.array([sample.roll_rad, sample.pitch_rad, sample.yaw_rad]) - self.error_rad
        return replace(sample, roll_rad=float(r), pitch_rad=float(p),
                       yaw_rad=math.remainder(float(y), math.tau),
                       roll_pitch_sigma_rad=float(np.sqrt(max(var[0], var[1]))),
                       yaw_sigma_rad=float(np.sqrt(var[2])))

    def learn(self, raw: AttitudeSample | None, fix: object) -> None:
        """After a fix solved with ``correct(raw)`` as its prior: on each axis the
        landmarks themselves fix better than the estimate already knows, the fix's
        attitude is the new estimate of the autopilot's error, good to the larger of the
        fix's own variance and the landmarks' alone (:meth:`landmarks_only`: what the same
        pixels will still miss by in the next frames); other axes keep their estimate.  A fix
        that rejected the prior teaches nothing: the landmarks and the estimate disagree, and
        which of them is wrong is not known (one misaligned plate's fix, taken as the
        truth, carried its 0.8 deg yaw error into the next second of the survey as JPEG)."""
        if raw is None or not isinstance(fix, PoseFix) or fix.attitude_prior != "used":
            return
        cov = np.asarray(fix.covariance, dtype=np.float64)
        own = self.landmarks_only(cov)
        grown = self._grow(raw)
        known = grown if grown is not None else np.array(
            [raw.roll_pitch_sigma_rad, raw.roll_pitch_sigma_rad, raw.yaw_sigma_rad]) ** 2
        learn = own < known
        if not np.any(learn) or (grown is None and not np.all(learn)):
            return  # nothing new, or not every axis of a first estimate
        var = np.maximum(np.maximum(np.diag(cov)[3:], own), self.floor_rad[[0, 0, 1]] ** 2)
        raw_rpy = np.array([raw.roll_rad, raw.pitch_rad, raw.yaw_rad])
        error = wrap_angle(raw_rpy - np.asarray(fix.attitude_rpy_rad))
        self.error_rad = np.where(learn, error, self.error_rad)
        self.var_rad2 = np.where(learn, var, known)
        self.t_us = fix.time_us
        self.learnt += 1

    def landmarks_only(self, cov: np.ndarray) -> np.ndarray:
        """The attitude variances (roll, pitch, yaw) a fix's landmarks give without the
        autopilot's attitude: the fix's information (``cov`` inverted) less the attitude
        prior's (:meth:`correct`'s last sigmas); infinite when they do not fix the pose."""
        try:
            info = np.linalg.inv(cov)
        except np.linalg.LinAlgError:
            return np.full(3, np.inf)
        if self.given_var is not None:
            info[3:, 3:] -= np.diag(1.0 / self.given_var)
        w, v = np.linalg.eigh(0.5 * (info + info.T))
        if not np.all(np.isfinite(w)) or w.min() <= _MIN_INFO_RATIO * w.max():
            return np.full(3, np.inf)
        return np.asarray(np.diag((v / w) @ v.T)[3:], dtype=np.float64)
