"""The fake autopilot's attitude error: what a real EKF's ATTITUDE carries, slowly varying.

A flight controller's attitude is an estimate.  Its error wanders over seconds (gyro bias,
accelerometer misalignment, a magnetometer disturbed by the frame) rather than jumping from
sample to sample, so each axis is a first-order Gauss-Markov process: stationary 1-sigma
``sigma``, correlation time ``tau``; ``e[k+1] = a e[k] + sigma sqrt(1 - a^2) n[k]`` with
``a = exp(-dt / tau)`` on a fixed grid, linearly interpolated between grid points.
Deterministic for a seed, and a function of time only (the same time gives the same error,
however often and in whatever order it is asked).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mavlink_bridge.vehicle import VehicleState


@dataclass(frozen=True)
class AttitudeErrorConfig:
    """1-sigma of the ATTITUDE error per axis and its correlation time (0 sigma: exact).

    The defaults (0.2 deg roll/pitch, 1 deg yaw) are a good autopilot's; the pose solver's
    own default prior is looser (2.5 / 5 deg, docs/decisions.md), and ``companion demo``
    states these to it unless ``--deployment-prior``."""

    roll_pitch_sigma_deg: float = field(default=0.2, metadata={"ge": 0})
    yaw_sigma_deg: float = field(default=1.0, metadata={"ge": 0})
    correlation_s: float = field(default=20.0, metadata={"gt": 0})
    step_s: float = field(default=0.05, metadata={"gt": 0})


class AttitudeDrift:
    """``error(t)`` (roll, pitch, yaw in rad) of a Gauss-Markov process per axis."""

    def __init__(self, config: AttitudeErrorConfig, seed: int = 0) -> None:
        self.config = config
        rp, yaw = math.radians(config.roll_pitch_sigma_deg), math.radians(config.yaw_sigma_deg)
        self._sigma = np.array([rp, rp, yaw])
        self._a = math.exp(-config.step_s / config.correlation_s)
        self._rng = np.random.default_rng(seed)
        self._grid = [self._rng.normal(0.0, 1.0, 3) * self._sigma]  # stationary start

    def error(self, t_s: float) -> tuple[float, float, float]:
        """The error at ``t_s`` seconds of flight (t < 0 counts as 0)."""
        if not np.any(self._sigma):
            return (0.0, 0.0, 0.0)
        x = max(t_s, 0.0) / self.config.step_s
        k = int(x)
        while len(self._grid) <= k + 1:
            noise = self._rng.normal(0.0, 1.0, 3) * self._sigma
            self._grid.append(self._a * self._grid[-1] + math.sqrt(1.0 - self._a**2) * noise)
        f = x - k
        e = (1.0 - f) * self._grid[k] + f * self._grid[k + 1]
        return float(e[0]), float(e[1]), float(e[2])

    def attitude(self, state: VehicleState) -> tuple[float, float, float]:
        """The estimated attitude: the true one plus :meth:`error` at the state's time (yaw
        wrapped to +-pi)."""
        r, p, y = state.attitude_rpy_rad
        er, ep, ey = self.error(state.time_s)
        return r + er, p + ep, math.remainder(y + ey, math.tau)
