"""The fake autopilot's attitude error: what a real EKF's ATTITUDE carries, slowly varying.

A flight controller's attitude is an estimate.  Its error wanders over seconds (gyro bias,
accelerometer misalignment, a magnetometer disturbed by the frame) rather than jumping from
sample to sample, so each axis is a first-order Gauss-Markov process: stationary 1-sigma
``sigma``, correlation time ``tau``; ``e[k+1] = a e[k] + sigma sqrt(1 - a^2) n[k]`` with
``a = exp(-dt / tau)`` on a fixed grid, linearly interpolated between grid points; the yaw
also drifts linearly (``yaw_drift_deg_min``, the gyro's uncorrected bias between heading
corrections).  Deterministic for a seed, and a function of time only (the same time gives
the same error, however often and in whatever order it is asked).

The defaults are a healthy EKF's, as sized by ArduPilot itself: EKF3 starts its attitude
at 0.1 rad (5.7 deg) 1-sigma per axis (``CovarianceInit``, ``rot_vec_var = sq(0.1f)``,
libraries/AP_NavEKF3/AP_NavEKF3_core.cpp) and converges to about a degree in tilt once the
accelerometers have levelled it; AP_AHRS calls two attitude estimates "inconsistent" only
beyond 10 deg roll/pitch and 20 deg yaw (``ATTITUDE_CHECK_THRESH_ROLL_PITCH_RAD`` /
``ATTITUDE_CHECK_THRESH_YAW_RAD``, libraries/AP_AHRS/AP_AHRS.cpp), and its yaw rests on a
magnetometer (or on the fixes) that drifts by degrees.  Hence 1 deg roll/pitch, 3 deg yaw
and 1 deg/min of yaw drift (docs/decisions.md, "The fake autopilot's attitude is an
EKF's").  ArduPilot reports no attitude variance (ATTITUDE has no such field; see
companion/sensors.py), so what a test tells the pose solver about this error is
:meth:`AttitudeErrorConfig.stated_sigmas_deg`, from this configuration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mavlink_bridge.vehicle import VehicleState


@dataclass(frozen=True)
class AttitudeErrorConfig:
    """1-sigma of the ATTITUDE error per axis, its correlation times and the yaw's linear
    drift (0 sigma, 0 drift: exact).

    The defaults are a real EKF's (module doc); ``companion demo`` and the sitl harness state
    :meth:`stated_sigmas_deg` to the pose solver unless ``--deployment-prior``."""

    roll_pitch_sigma_deg: float = field(default=1.0, metadata={"ge": 0})
    yaw_sigma_deg: float = field(default=3.0, metadata={"ge": 0})
    correlation_s: float = field(default=20.0, metadata={"gt": 0})  # roll and pitch
    yaw_correlation_s: float = field(default=120.0, metadata={"gt": 0})
    yaw_drift_deg_min: float = 1.0
    step_s: float = field(default=0.05, metadata={"gt": 0})

    def stated_sigmas_deg(self, seconds: float) -> tuple[float, float]:
        """The (roll/pitch, yaw) 1-sigma that honestly describes this error over a flight of
        ``seconds``: the yaw's stationary sigma and its drift at the end, root-sum-squared."""
        drift = abs(self.yaw_drift_deg_min) * max(seconds, 0.0) / 60.0
        return self.roll_pitch_sigma_deg, math.hypot(self.yaw_sigma_deg, drift)


class AttitudeDrift:
    """``error(t)`` (roll, pitch, yaw in rad) of a Gauss-Markov process per axis."""

    def __init__(self, config: AttitudeErrorConfig, seed: int = 0) -> None:
        self.config = config
        rp, yaw = math.radians(config.roll_pitch_sigma_deg), math.radians(config.yaw_sigma_deg)
        self._sigma = np.array([rp, rp, yaw])
        tau = np.array([config.correlation_s, config.correlation_s, config.yaw_correlation_s])
        self._a = np.exp(-config.step_s / tau)
        self._drift_rad_s = math.radians(config.yaw_drift_deg_min) / 60.0
        self._rng = np.random.default_rng(seed)
        self._grid = [self._rng.normal(0.0, 1.0, 3) * self._sigma]  # stationary start

    def error(self, t_s: float) -> tuple[float, float, float]:
        """The error at ``t_s`` seconds of flight (t < 0 counts as 0)."""
        t_s = max(t_s, 0.0)
        if not np.any(self._sigma):
            return (0.0, 0.0, self._drift_rad_s * t_s)
        x = t_s / self.config.step_s
        k = int(x)
        while len(self._grid) <= k + 1:
            noise = self._rng.normal(0.0, 1.0, 3) * self._sigma
            self._grid.append(self._a * self._grid[-1] + np.sqrt(1.0 - self._a**2) * noise)
        f = x - k
        e = (1.0 - f) * self._grid[k] + f * self._grid[k + 1]
        return float(e[0]), float(e[1]), float(e[2]) + self._drift_rad_s * t_s

    def attitude(self, state: VehicleState) -> tuple[float, float, float]:
        """The estimated attitude: the true one plus :meth:`error` at the state's time (yaw
        wrapped to +-pi)."""
        r, p, y = state.attitude_rpy_rad
        er, ep, ey = self.error(state.time_s)
        return r + er, p + ep, math.remainder(y + ey, math.tau)
