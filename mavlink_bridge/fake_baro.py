"""The fake autopilot's barometer and the height source its parameters choose.

A real autopilot configured as the companion's profiles are takes its height from the
barometer, not from the vision fixes:

* ArduPilot ``EK3_SRC1_POSZ``: 1 baro (the default), 6 ExtNav
  (libraries/AP_NavEKF/AP_NavEKF_Source.cpp).  EKF3 ``selectHeightForFusion``
  (libraries/AP_NavEKF3/AP_NavEKF3_PosVelFusion.cpp) fuses the external navigation's down
  only when the source is ExtNav and its data is fresh (``extNavDataIsFresh``: newer than
  500 ms); otherwise it falls back to the barometer (``lostExtNavHgt``), keeping a filtered
  offset so that the switch does not jump (``calcFiltBaroOffset``), and resets the height to
  the new source's measurement when the source changes (``ResetPositionD``).  At start
  (``InitialiseFilterBootstrap``, AP_NavEKF3_core.cpp) it sets the height from the height
  measurement (``ResetHeight``: the barometer, since no ExtNav data is fresh yet) with the
  variance ``EK3_ALT_M_NSE``^2 -- before any fix, so a vehicle taken off by hand has its
  height from the start.  The barometer's noise in the filter is ``EK3_ALT_M_NSE``, copter
  default 2.0 m (libraries/AP_NavEKF3/AP_NavEKF3.cpp).
* PX4: ``EKF2_HGT_REF`` 0 baro, 1 GNSS (the default), 2 range, 3 vision, reboot required
  (src/modules/ekf2/ekf2_params.c);
  the vision's down is fused only when ``EKF2_EV_CTRL`` has bit 1 (vertical position)
  (src/modules/ekf2/params_external_vision.yaml); without GNSS the barometer
  (``EKF2_BARO_CTRL`` default 1) gives the height, noise ``EKF2_BARO_NOISE`` 3.5 m
  (src/modules/ekf2/params_barometer.yaml).  The fake takes the vision's down whenever that
  bit is set (whatever the reference: the conservative reading, the echo loop possible).

The simulated barometer copies ArduPilot SITL: white noise ``SIM_BARO_RND`` 0.2 m and a
drift ``SIM_BARO_DRIFT`` (m/s; SITL's default 0, libraries/SITL/SITL.cpp).  The fake's drift
is not 0: a constant rate drawn per seed with a 1-sigma of ``drift_m_s`` = 0.001 m/s
(3.6 m/h, about 0.4 hPa/h: more than the ordinary weather's change of pressure, which
stays under 1 hPa in 3 h), so a 2-minute flight's barometer wanders by about 0.1 m.  It is
zeroed on the ground at boot (AP_Baro calibrates its ground pressure then): a vehicle
hovering at 4 m reads 4 m plus its error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

HeightSource = Literal["baro", "extnav", "fixes"]
#: EKF3's ``extNavDataIsFresh``: the external navigation's down is used while newer than this
EXTNAV_FRESH_S = 0.5
_ARDUPILOT_POSZ_EXTNAV = 6
_PX4_EV_CTRL_VPOS = 2


@dataclass(frozen=True)
class BaroConfig:
    """The simulated barometer (module doc has the sources)."""

    noise_m: float = 0.2  # SITL SIM_BARO_RND
    drift_m_s: float = 0.001  # 1-sigma of the constant drift rate (SITL SIM_BARO_DRIFT: 0)
    period_s: float = 0.05  # 20 Hz (PX4 EKF2_BARO_RATE default 20 Hz)


class SimBarometer:
    """Height above the boot point: the truth's, plus a drift and white noise."""

    def __init__(self, config: BaroConfig, seed: int = 0) -> None:
        self.config = config
        self._rng = np.random.default_rng(seed + 2027)
        self.drift_rate_m_s = float(self._rng.normal(0.0, config.drift_m_s))
        self.t0_s: float | None = None
        self.last_s = -math.inf

    def due(self, t_s: float) -> bool:
        return t_s - self.last_s >= self.config.period_s - 1e-9

    def read(self, t_s: float, true_down_m: float) -> float:
        """One reading (m up) at ``t_s``; the drift counts from the first reading."""
        if self.t0_s is None:
            self.t0_s = t_s
        self.last_s = t_s
        drift = self.drift_rate_m_s * (t_s - self.t0_s)
        return -true_down_m + drift + float(self._rng.normal(0.0, self.config.noise_m))


def height_source(profile: str, params: Mapping[str, float]) -> HeightSource:
    """Where the autopilot's height comes from with these parameter values."""
    if profile == "px4":
        vpos = int(params.get("EKF2_EV_CTRL", 0)) & _PX4_EV_CTRL_VPOS
        return "extnav" if vpos else "baro"
    posz = int(params.get("EK3_SRC1_POSZ", 1))
    return "extnav" if posz == _ARDUPILOT_POSZ_EXTNAV else "baro"
