"""The fake autopilot's own estimator: what a real EKF does with vision fixes.

Per axis (north, east, down) a two-state Kalman filter, position and velocity, is propagated
with the simulated IMU -- the true acceleration plus an accelerometer bias and white noise --
and corrected by the vision fixes it accepts.  Every rule copies the real autopilots:

* Delay: a fix is compared with the estimate ``delay_ms`` before its stamp (ArduPilot
  ``VISO_DELAY_MS``, default 10, libraries/AP_VisualOdom/AP_VisualOdom.cpp; PX4
  ``EKF2_EV_DELAY``, default 0 ms, src/modules/ekf2/params_external_vision.yaml).
* Fusion time horizon (ArduPilot): EKF3 fuses on a delayed horizon, ``maxTimeDelay_ms``
  behind its newest IMU sample, and a measurement stamped older than that is moved up to it
  (``writeExtNavData``: the stamp minus ``delay_ms`` and half the 12 ms filter step, then
  ``MAX(timeStamp_ms, imuDataDelayed.time_ms)``), so a late fix is compared with the
  estimate at the horizon, not at its stamp.  ``setup_core``: ``maxTimeDelay_ms`` is the
  largest of ``EK3_HGT_DELAY`` (60), ``EK3_FLOW_DELAY`` (10), ``EK3_BCN_DELAY`` (50) and
  ``EKF_TARGET_DT_MS`` (12), and ``min(VISO_DELAY_MS, 250)`` with visual odometry on (a
  GNSS lag only when a source set uses GNSS, which external navigation here does not):
  60 ms with the defaults (:attr:`EstimatorConfig.horizon_floor_ms`).  ``setup_core`` runs
  when the EKF starts: a ``VISO_DELAY_MS`` set later widens the horizon only from the next
  boot (:meth:`FakeEstimator.set_parameter`'s ``at_boot``).  PX4's EKF2 has a
  horizon too (``EKF2_DELAY_MAX``; a sample up to 100 ms older than it is fused at it,
  older ones dropped, ``RingBuffer::pop_first_older_than``); its default differs between
  versions (110 or 200 ms) and is not modelled: the PX4 profile compares at the stamp.
* Noise (:func:`fix_variances`): ArduPilot reduces the fix's covariance to one position
  error for all three axes, ``posErr = cbrt(c0^2 + c6^2 + c11^2)`` (0 when ``c0`` is NaN;
  libraries/GCS_MAVLink/GCS_Common.cpp ``handle_common_vision_position_estimate_data``),
  constrained to [``VISO_POS_M_NSE`` (default 0.2 m), 100] (AP_VisualOdom_MAV) and fused as
  ``R = sq(constrain(posErr, 0.01, 10))`` north and east (EKF3 ``FuseVelPosNED``) and
  ``sq(constrain(posErr, 0.1, 10))`` down (``selectHeightForFusion``); PX4 keeps the three
  variances, each floored by ``EKF2_EVP_NOISE`` squared (default 0.1 m, with
  ``EKF2_EV_NOISE_MD`` 0; src/modules/ekf2/EKF/aid_sources/external_vision/ev_pos_control.cpp).
  ../shared/MAVLINK.md, "Covariance and reset_counter".
* Gate: the horizontal innovation test against **this estimate** (never the truth):
  ArduPilot EKF3 ``(nu_N^2 + nu_E^2) / (S_N + S_E) <= gate^2`` (``FuseVelPosNED``
  ``posTestRatio``, ``EK3_POS_I_GATE`` default 500 = 5 sigma), PX4 ``nu_N^2/S_N + nu_E^2/S_E
  <= gate^2`` (``EKF2_EVP_GATE`` default 5), S = P + R.
  The vertical axis has its own test.
* Process noise of the filter: ``EK3_ACC_P_NSE`` / PX4 ``EKF2_ACC_NOISE``, both 0.35 m/s^2.
* Height (:mod:`mavlink_bridge.fake_baro`): from the simulated barometer, fused with the
  variance ``baro_noise_m``^2 (ArduPilot ``EK3_ALT_M_NSE`` 2.0 m; PX4 ``EKF2_BARO_NOISE``
  3.5 m) and set from it at start, before any fix, as EKF3's bootstrap does; the fixes' down
  is fused only when :attr:`FakeEstimator.height_source` is ``"extnav"`` (the autopilot's
  parameters say so: ``EK3_SRC1_POSZ`` 6, PX4 ``EKF2_EV_CTRL`` bit 1) and while they are
  fresh.  ``"fixes"`` is the old fake (no barometer; the height unset until the first fix,
  then every fix's down fused): only for a test that asks for it explicitly.
* Health: ArduPilot's EKF_STATUS_REPORT flags are 0x33f with external navigation fused; the
  horizontal position flags drop (0x25) about ``outage_flags_s`` = 6 s into a vision outage
  (../shared/MAVLINK.md "What a real ArduCopter did"); PX4 declares the horizontal position
  invalid after ``EKF2_NOAID_TOUT`` (default 5 s) without aiding.

The reported attitude is the estimate: the truth plus an error that starts at
``attitude.initial_deg`` and drifts in yaw at ``attitude.yaw_drift_deg_min``.  In the
``coupled`` mode the attitude error also leaks gravity into the propagated acceleration (a
tilt error of d rad is an acceleration error of g d) and every fused fix pulls the attitude
in proportion to its innovation, as a real EKF's position-attitude cross-covariance does:
fixes that follow the reported attitude then drag the attitude with them.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from mavlink_bridge.fake_baro import EXTNAV_FRESH_S, BaroConfig, HeightSource, SimBarometer
from mavlink_bridge.params import EKF3_HORIZON_FLOOR_MS

#: how the fused noise comes from a fix's covariance: "ardupilot" one error for all axes,
#: "px4" one per axis (:func:`fix_variances`)
NoiseModel = Literal["ardupilot", "px4"]

GRAVITY_M_S2 = 9.80665
EKF_FLAGS_HEALTHY = 0x33F  # attitude, velocities, positions, pred pos horiz rel/abs (ArduPilot)
EKF_FLAGS_NO_HORIZ = 0x25  # attitude, vertical velocity, vertical position only
EKF_FLAGS_NO_ORIGIN = 0x07


@dataclass(frozen=True)
class AttitudeModel:
    """The estimated attitude's error: initial (roll, pitch, yaw) in degrees, yaw drift in
    degrees per minute, and the coupling of ``coupled`` mode (rad of tilt per metre of
    innovation of one fused fix)."""

    initial_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_drift_deg_min: float = 0.0
    coupled: bool = False
    coupling_rad_per_m: float = field(default=0.005, metadata={"ge": 0})


@dataclass(frozen=True)
class EstimatorConfig:
    """The fake EKF's parameters; :func:`estimator_defaults` gives each profile's."""

    delay_ms: float = 10.0
    # ArduPilot EKF3's fusion time horizon behind now before VISO_DELAY_MS (module doc);
    # None: a fix is compared at its stamp however late (PX4's horizon is not modelled)
    horizon_floor_ms: float | None = EKF3_HORIZON_FLOOR_MS
    # EKF3 moves a stamp back by half its filter step (localFilterTimeStep_ms / 2, 12 ms)
    half_step_ms: float = 6.0
    noise_floor_m: float = 0.2
    # how a fix's covariance becomes the fused noise (:func:`fix_variances`)
    noise_model: NoiseModel = "ardupilot"
    gate_sigma: float = 5.0
    filter_accel_noise_m_s2: float = 0.35
    # the simulated IMU: bias (1-sigma per axis, constant) and white noise density
    accel_bias_m_s2: float = 0.03
    accel_noise_m_s2_rthz: float = 0.02
    outage_flags_s: float = 6.0
    attitude: AttitudeModel = field(default_factory=AttitudeModel)
    # the height: "baro" or "extnav" (a fake autopilot sets it from its parameters,
    # fake_baro.height_source), "fixes" the old fake's (module doc)
    height_source: HeightSource = "baro"
    baro_noise_m: float = 2.0  # EK3_ALT_M_NSE (PX4 EKF2_BARO_NOISE 3.5)
    baro: BaroConfig = field(default_factory=BaroConfig)


def estimator_defaults(profile: str) -> EstimatorConfig:
    """The real autopilot's defaults (module doc has the sources)."""
    if profile == "px4":
        return EstimatorConfig(delay_ms=0.0, horizon_floor_ms=None, half_step_ms=0.0,
                               noise_floor_m=0.1, noise_model="px4", outage_flags_s=5.0,
                               baro_noise_m=3.5)
    return EstimatorConfig()


def fix_variances(var_ned: tuple[float, float, float], floor_m: float,
                  model: NoiseModel) -> np.ndarray:
    """The N, E, D noise variances an autopilot fuses a fix with, from the fix's position
    variances (the covariance's c0, c6, c11; NaN: unknown) and its noise floor (module
    doc).  ArduPilot: one error, ``posErr = cbrt(c0^2 + c6^2 + c11^2)`` (0 for a NaN c0),
    constrained to [floor, 100] by AP_VisualOdom (a NaN to the middle, as AP_Math's
    ``constrain_value`` does), then fused by EKF3 at ``sq(constrain(posErr, 0.01, 10))``
    north and east and ``sq(constrain(posErr, 0.1, 10))`` down.  PX4: each variance at
    least the floor squared (a non-finite one: the floor)."""
    floor2 = floor_m ** 2
    if model == "px4":
        return np.array([v if math.isfinite(v) and v > floor2 else floor2 for v in var_ned])
    c0, c6, c11 = var_ned
    # float products overflow to inf (then 100), never raise
    pos_err = 0.0 if math.isnan(c0) else math.cbrt(c0 * c0 + c6 * c6 + c11 * c11)
    pos_err = (floor_m + 100.0) / 2 if math.isnan(pos_err) else min(max(pos_err, floor_m), 100.0)
    horizontal, down = min(max(pos_err, 0.01), 10.0), min(max(pos_err, 0.1), 10.0)
    return np.array([horizontal, horizontal, down]) ** 2


@dataclass(frozen=True)
class Verdict:
    accepted: bool
    reason: str
    innovation_m: float  # horizontal+vertical innovation norm against the estimate


class FakeEstimator:
    """See module doc.  Times are the autopilot's flight clock in seconds."""

    def __init__(self, config: EstimatorConfig, seed: int = 0) -> None:
        self.config = config
        self._rng = np.random.default_rng(seed + 1009)
        self.bias = self._rng.normal(0.0, config.accel_bias_m_s2, 3)
        self.x = np.zeros((3, 2))
        self.P = np.tile(np.diag([100.0, 1.0]), (3, 1, 1))
        self.initialised = False  # horizontal: set by the first fix
        self.height_source: HeightSource = config.height_source
        # the parameters' current values (the autopilot's VISO_POS_M_NSE / VISO_DELAY_MS or
        # EKF2_EVP_NOISE / EKF2_EV_DELAY, set live: :meth:`set_parameter`)
        self.noise_floor_m = config.noise_floor_m
        self.delay_ms = config.delay_ms
        self.horizon_delay_ms = config.delay_ms  # VISO_DELAY_MS as EKF3's setup_core read it
        self.height_initialised = False  # vertical: by the barometer at start, or a fix
        self._height_active: HeightSource = "baro"  # what the down follows now
        self._last_down_fix_s = -math.inf
        self._baro_offset_m = 0.0  # barometer reading minus the height estimate (extnav)
        self.baro = SimBarometer(config.baro, seed)
        self.t_s: float | None = None
        self.t0_s = 0.0  # the first propagation (boot): outages count from it until a fix
        self.last_fused_s: float | None = None
        self.fused = 0
        self.rejected = 0
        a = config.attitude
        self.tilt_err = np.radians([a.initial_deg[0], a.initial_deg[1]])  # about N, E axes
        self.yaw_err = math.radians(a.initial_deg[2])
        self._history: collections.deque[tuple[float, np.ndarray]] = collections.deque(
            maxlen=200)

    # ------------------------------------------------------------ propagation
    def predict(self, t_s: float, true_accel_ned: np.ndarray) -> None:
        """Propagate to ``t_s`` with the IMU's acceleration (truth + bias + noise)."""
        if self.t_s is None:
            self.t_s = self.t0_s = t_s
            return
        dt = t_s - self.t_s
        if dt <= 0:
            return
        self.t_s = t_s
        a = self.config.attitude
        self.yaw_err += math.radians(a.yaw_drift_deg_min) / 60.0 * dt
        accel = np.asarray(true_accel_ned, float) + self.bias
        accel += self._rng.normal(0.0, self.config.accel_noise_m_s2_rthz / math.sqrt(dt), 3)
        if a.coupled:
            accel += self._attitude_accel_error(np.asarray(true_accel_ned, float))
        # no horizontal position source yet: constant-position mode at the origin; the
        # height runs from the barometer's first reading on
        axes = [k for k, on in enumerate((self.initialised,) * 2 + (self.height_initialised,))
                if on]
        if not axes:
            return
        f = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.config.filter_accel_noise_m_s2 ** 2
        qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        for k in axes:
            self.x[k] = f @ self.x[k] + np.array([0.5 * dt * dt, dt]) * accel[k]
            self.P[k] = f @ self.P[k] @ f.T + qm
        self._history.append((t_s, self.x[:, 0].copy()))

    def observe_baro(self, t_s: float, true_down_m: float) -> None:
        """The barometer at ``t_s`` (at its own rate): sets the height at start, is fused
        while it is the active height source, else tracks its offset (module doc)."""
        if self.height_source == "fixes" or not self.baro.due(t_s):
            return
        height = self.baro.read(t_s, true_down_m)
        extnav = self.height_source == "extnav" and t_s - self._last_down_fix_s <= EXTNAV_FRESH_S
        if extnav:
            # calcFiltBaroOffset: low-passed, about 1 s at 20 Hz
            self._baro_offset_m += 0.05 * (height + self.x[2, 0] - self._baro_offset_m)
            return
        self._height_active = "baro"
        z, r = -(height - self._baro_offset_m), self.config.baro_noise_m ** 2
        if not self.height_initialised:  # InitialiseFilterBootstrap -> ResetHeight
            self.x[2] = (z, 0.0)
            self.P[2] = np.diag([r, 1.0])
            self.height_initialised = True
            return
        s = self.P[2][0, 0] + r
        if (z - self.x[2, 0]) ** 2 / s <= self.config.gate_sigma ** 2:  # EK3_HGT_I_GATE 500
            gain = self.P[2][:, 0] / s
            self.x[2] += gain * (z - self.x[2, 0])
            self.P[2] = self.P[2] - np.outer(gain, self.P[2][0, :])

    def _attitude_accel_error(self, accel_ned: np.ndarray) -> np.ndarray:
        """A tilt error leaks gravity (g d); a yaw error rotates the horizontal acceleration."""
        tn, te = self.tilt_err
        err = np.array([-GRAVITY_M_S2 * te, GRAVITY_M_S2 * tn, 0.0])
        err[0] += -self.yaw_err * accel_ned[1]
        err[1] += self.yaw_err * accel_ned[0]
        return err

    # ------------------------------------------------------------ fusion
    def position_at(self, t_s: float) -> np.ndarray:
        """The estimated position at ``t_s`` (from the recent history; now if newer)."""
        for t, pos in reversed(self._history):
            if t <= t_s:
                return pos
        return self.x[:, 0].copy()

    def measured_at(self, t_s: float, now_s: float) -> float:
        """When the autopilot takes a fix stamped ``t_s`` (its clock) and arriving at
        ``now_s`` to have been measured: ``delay_ms`` and half a filter step before its
        stamp, but not before ArduPilot's fusion time horizon (module doc)."""
        t = t_s - (self.delay_ms + self.config.half_step_ms) / 1000.0
        floor = self.config.horizon_floor_ms
        if floor is None:
            return t
        horizon_ms = max(floor, min(self.horizon_delay_ms, 250.0))
        return max(t, now_s - horizon_ms / 1000.0)

    def fuse(self, t_s: float, z_ned: tuple[float, float, float],
             var_ned: tuple[float, float, float], reset: bool = False,
             now_s: float | None = None) -> Verdict:
        """One vision position stamped ``t_s`` and arriving at ``now_s`` (default: at its
        stamp), compared with the estimate at :meth:`measured_at`."""
        z = np.asarray(z_ned, float)
        r = fix_variances(var_ned, self.noise_floor_m, self.config.noise_model)
        down = self._down_from_fixes(t_s)
        if not self.initialised or reset:
            # the first fix (or a reset_counter change) sets the horizontal position, and
            # the height when it comes from the fixes (EKF3 ResetPositionD on a source change)
            with_down = down == "reset" or (bool(down) and (reset or not self.height_initialised))
            axes = [0, 1, 2] if with_down else [0, 1]
            for k in axes:
                self.x[k] = (z[k], self.x[k, 1] if self.initialised else 0.0)
                self.P[k] = np.diag([r[k], self.P[k][1, 1] if self.initialised else 1.0])
            self.height_initialised = self.height_initialised or 2 in axes
            self.initialised = True
            self._history.clear()
            self.last_fused_s = t_s
            return Verdict(True, "reset" if reset else "fused", 0.0)  # the first sets it
        if down == "reset":
            self.x[2, 0], self.P[2][0, 0], self.P[2][0, 1], self.P[2][1, 0] = z[2], r[2], 0, 0
        nu = z - self.position_at(self.measured_at(t_s, t_s if now_s is None else now_s))
        s = np.array([self.P[k][0, 0] + r[k] for k in range(3)])
        gate2 = self.config.gate_sigma ** 2
        innovation = float(np.linalg.norm(nu))
        if self._horizontal_ratio(nu, s) > gate2:
            self.rejected += 1
            return Verdict(False, "innovation_gate", innovation)
        fused_axes = range(3) if down == "fuse" and nu[2] ** 2 / s[2] <= gate2 else range(2)
        for k in fused_axes:
            gain = self.P[k][:, 0] / s[k]
            self.x[k] += gain * nu[k]
            self.P[k] = self.P[k] - np.outer(gain, self.P[k][0, :])
        if self.config.attitude.coupled:
            self._pull_attitude(nu)
        self.fused += 1
        self.last_fused_s = t_s
        return Verdict(True, "fused", innovation)

    def _horizontal_ratio(self, nu: np.ndarray, s: np.ndarray) -> float:
        """The horizontal innovation test's ratio (gate^2 rejects): EKF3 sums both axes,
        ``(nuN^2 + nuE^2) / (S_N + S_E)`` (``FuseVelPosNED``, ``posTestRatio``); for PX4
        the per-axis ratios are summed (not checked against EKF2: the stricter reading)."""
        if self.config.noise_model == "ardupilot":
            return float((nu[0] ** 2 + nu[1] ** 2) / (s[0] + s[1]))
        return float(nu[0] ** 2 / s[0] + nu[1] ** 2 / s[1])

    def set_parameter(self, name: str, value: float, at_boot: bool = False) -> None:
        """A parameter set on the autopilot that this estimator reads at every fix, as
        ArduPilot's AP_VisualOdom and PX4's EKF2 do; other names are not its own.  The
        fusion horizon takes ``VISO_DELAY_MS`` only ``at_boot`` (EKF3's ``setup_core``)."""
        if name in ("VISO_POS_M_NSE", "EKF2_EVP_NOISE"):
            self.noise_floor_m = value
        elif name in ("VISO_DELAY_MS", "EKF2_EV_DELAY"):
            self.delay_ms = value
            if at_boot:
                self.horizon_delay_ms = value

    def _down_from_fixes(self, t_s: float) -> str:
        """Whether this fix's down is used: "" no (barometer), "fuse", or "reset" (the
        height source changes from the barometer to the fixes: EKF3 ResetPositionD)."""
        if self.height_source == "fixes":
            return "fuse"
        if self.height_source != "extnav":
            return ""
        self._last_down_fix_s = t_s
        if self._height_active != "extnav":
            self._height_active = "extnav"
            return "reset"
        return "fuse"

    def _pull_attitude(self, nu: np.ndarray) -> None:
        """A fix north of the estimate says the acceleration north was under-estimated: the
        tilt that explains it changes (dN = -g tE, so tE decreases; dE = g tN)."""
        k = self.config.attitude.coupling_rad_per_m
        self.tilt_err += k * np.array([nu[1], -nu[0]])

    # ------------------------------------------------------------ outputs
    def position(self) -> tuple[float, float, float]:
        n, e, d = (float(v) for v in self.x[:, 0])
        return n, e, d

    def velocity(self) -> tuple[float, float, float]:
        n, e, d = (float(v) for v in self.x[:, 1])
        return n, e, d

    def outage_s(self, t_s: float) -> float:
        """Seconds since the last fused fix (since boot before the first)."""
        return t_s - (self.t0_s if self.last_fused_s is None else self.last_fused_s)

    def horizontal_ok(self, t_s: float) -> bool:
        return self.outage_s(t_s) <= self.config.outage_flags_s

    def flags(self, t_s: float, origin_set: bool) -> int:
        """ArduPilot's EKF_STATUS_REPORT flags."""
        if not origin_set:
            return EKF_FLAGS_NO_ORIGIN
        return EKF_FLAGS_HEALTHY if self.horizontal_ok(t_s) else EKF_FLAGS_NO_HORIZ

    def attitude(self, true_rpy: tuple[float, float, float]) -> tuple[float, float, float]:
        """The reported attitude: the truth plus the estimate's error, tilt rotated into
        the body's heading."""
        r, p, y = true_rpy
        tn, te = self.tilt_err
        c, s = math.cos(y), math.sin(y)
        roll_err, pitch_err = c * tn + s * te, -s * tn + c * te
        return r + roll_err, p + pitch_err, math.remainder(y + self.yaw_err, math.tau)
