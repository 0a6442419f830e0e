"""What the fake autopilot does with incoming vision messages: the autopilots' rules.

Each rule below is one the real autopilots apply (../shared/MAVLINK.md has the sources):

ArduPilot: ODOMETRY only with frame_id LOCAL_FRD (20) and child_frame_id BODY_FRD (12);
samples < 20 ms apart are discarded (EKF3); VPE is blocked when VISO_QUAL_MIN > 0; a quality
below VISO_QUAL_MIN is rejected; a new ``reset_counter`` resets instead of fusing.
PX4: ODOMETRY frame_id LOCAL_NED/ENU/FRD/FLU; estimator_type MOCAP is published to a topic EKF2
never reads (ignored); quality below EKF2_EV_QMIN rejected; stamps are converted with the
TIMESYNC offset once synced, else replaced by the arrival time.  ArduPilot's stamps go through
its jitter correction (:class:`JitterCorrection`).
Both: non-finite pose -> rejected.  The innovation gate is the fake's estimator's
(:mod:`mavlink_bridge.fake_ekf`, against its own estimate); the old gate against the true
state (:meth:`VisionJudge.judge`) stays for the permissive fake only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from mavlink_bridge.messages import MAV_FRAME_BODY_FRD, MAV_FRAME_LOCAL_FRD
from mavlink_bridge.vehicle import VehicleState

Profile = Literal["ardupilot", "px4"]
MAV_ESTIMATOR_TYPE_MOCAP = 6
_PX4_ODOM_FRAMES = {1: "LOCAL_NED", 4: "LOCAL_ENU", 20: "LOCAL_FRD", 21: "LOCAL_FLU"}
_PX4_ESTIMATORS = {0, 1, 2, 3}  # UNKNOWN NAIVE VISION VIO
_EV_MIN_SPACING_US = 20_000


@dataclass(frozen=True)
class FakeRules:
    """Autopilot parameters the fake honours (names after the real parameters)."""

    quality_min: int = 0  # VISO_QUAL_MIN / EKF2_EV_QMIN
    gate_sigma: float = 5.0  # EKF2_EVP_GATE default; ArduPilot's EK3_EXTNAV gate is similar
    position_noise_floor_m: float = 0.1  # VISO_POS_M_NSE / EKF2_EVP_NOISE
    delay_ms: float = 10.0  # VISO_DELAY_MS / EKF2_EV_DELAY
    max_stamp_age_ms: float = 500.0  # older (after time conversion) falls out of the buffer


class JitterCorrection:
    """ArduPilot's time for an offboard stamp (libraries/AP_Common/JitterCorrection.cpp,
    used for VISION_POSITION_ESTIMATE and ODOMETRY through GCS_MAVLINK's
    ``correct_offboard_timestamp_usec_to_ms``): the stamp plus the link's offset, the
    smallest (local - stamp) seen; that minimum is re-taken every ``convergence_loops``
    samples (clock drift), and a stamp more than ``max_lag_ms`` behind is clamped there.
    So a fix that took longer than the quickest one is placed that much before its arrival:
    its age, not zero."""

    def __init__(self, max_lag_ms: int = 500, convergence_loops: int = 100) -> None:
        self.max_lag_us = max_lag_ms * 1000
        self.convergence_loops = convergence_loops
        self.link_offset_us: int | None = None
        self.min_sample_us = 0
        self.min_sample_counter = 0

    def age_ms(self, offboard_us: int, local_us: int) -> float:
        """How long before ``local_us`` ArduPilot takes the sample stamped ``offboard_us``
        to have been made (>= 0, at most ``max_lag_ms``)."""
        diff = local_us - offboard_us
        if self.link_offset_us is None or diff < self.link_offset_us:
            self.link_offset_us = diff  # "a timestamp from the future": adjust down
        estimate = offboard_us + self.link_offset_us
        if estimate + self.max_lag_us < local_us:  # too far in the past: assume max lag
            estimate = local_us - self.max_lag_us
            self.link_offset_us = estimate - offboard_us
        if self.min_sample_counter == 0:
            self.min_sample_us = diff
        self.min_sample_counter += 1
        self.min_sample_us = min(self.min_sample_us, diff)
        if self.min_sample_counter == self.convergence_loops:
            self.link_offset_us = self.min_sample_us
            self.min_sample_counter = 0
        return (local_us - estimate) / 1000.0


@dataclass
class VisionRecord:
    """One vision message as the fake autopilot received it."""

    name: str
    arrival_s: float  # fake autopilot time since boot
    time_usec: int
    position_ned_m: tuple[float, float, float]
    frame_id: int
    child_frame_id: int
    estimator_type: int
    quality: int
    reset_counter: int
    accepted: bool
    reason: str
    innovation_m: float = math.nan
    stamp_age_ms: float = math.nan
    truth_error_m: float = math.nan  # for scoring only: never used to accept a fix

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("innovation_m", "stamp_age_ms", "truth_error_m"):
            if not math.isfinite(d[k]):
                d[k] = None
        return d


@dataclass
class VisionJudge:
    """Applies :class:`FakeRules` for one profile; keeps the state the rules need."""

    profile: Profile
    rules: FakeRules = field(default_factory=FakeRules)
    last_stamp_us: int | None = None
    last_reset_counter: int | None = None

    def reset(self) -> None:
        self.last_stamp_us = None
        self.last_reset_counter = None

    def screen(self, name: str, f: Mapping[str, Any], stamp_age_ms: float
               ) -> tuple[str | None, bool]:
        """-> (reason to reject or None, reset_counter changed) -- every rule but the gate."""
        reason = self._static_checks(name, f)
        if reason is not None:
            return reason, False
        if not (-10.0 <= stamp_age_ms <= self.rules.max_stamp_age_ms):
            return "stamp_out_of_range", False
        stamp = int(f["time_usec"] if name == "ODOMETRY" else f["usec"])
        if self.profile == "ardupilot" and self.last_stamp_us is not None:
            if stamp - self.last_stamp_us < _EV_MIN_SPACING_US:
                return "under_20ms_apart", False
        reset = int(f.get("reset_counter", 0))
        self.last_stamp_us = stamp
        changed = self.last_reset_counter is not None and reset != self.last_reset_counter
        self.last_reset_counter = reset
        return None, changed

    def judge(self, name: str, f: Mapping[str, Any], truth: VehicleState,
              stamp_age_ms: float) -> tuple[bool, str, float]:
        """The permissive fake (``FakeAutopilotConfig(judge="truth")``): the gate against the
        true state.  -> (accepted, reason, innovation_m)."""
        reason, reset = self.screen(name, f, stamp_age_ms)
        if reason is not None:
            return False, reason, math.nan
        pos = (float(f["x"]), float(f["y"]), float(f["z"]))
        innovation = math.dist(pos, truth.position_ned_m)
        if reset:
            return True, "reset", innovation
        if not self._inside_gate(pos, truth, f, name):
            return False, "innovation_gate", innovation
        return True, "fused", innovation

    def _static_checks(self, name: str, f: Mapping[str, Any]) -> str | None:
        pose = [f["x"], f["y"], f["z"]]
        pose += list(f["q"]) if name == "ODOMETRY" else [f["roll"], f["pitch"], f["yaw"]]
        if not all(math.isfinite(float(v)) for v in pose):
            return "non_finite"
        qmin = self.rules.quality_min
        if name == "VISION_POSITION_ESTIMATE":
            if self.profile == "ardupilot" and qmin > 0:
                return "vpe_blocked_by_quality_min"
            return None
        if self.profile == "ardupilot":
            if f["frame_id"] != MAV_FRAME_LOCAL_FRD or f["child_frame_id"] != MAV_FRAME_BODY_FRD:
                return "odometry_frames_not_20_12"
        else:
            if f["frame_id"] not in _PX4_ODOM_FRAMES:
                return "odometry_frame_unsupported"
            if f["estimator_type"] == MAV_ESTIMATOR_TYPE_MOCAP:
                return "mocap_not_fused_by_ekf2"
            if f["estimator_type"] not in _PX4_ESTIMATORS:
                return "estimator_type_unsupported"
        if int(f["quality"]) < qmin:
            return "quality_below_min"
        return None

    def _inside_gate(self, pos: tuple[float, float, float], truth: VehicleState,
                     f: Mapping[str, Any], name: str) -> bool:
        """Per-axis test |innovation| <= gate * sigma, sigma^2 = max(var, floor^2)."""
        diag = position_variances(name, f)
        floor2 = self.rules.position_noise_floor_m ** 2
        for p, t, var in zip(pos, truth.position_ned_m, diag, strict=True):
            v = floor2 if not math.isfinite(var) else max(var, floor2)
            if abs(p - t) > self.rules.gate_sigma * math.sqrt(v):
                return False
        return True


def position_variances(name: str, f: Mapping[str, Any]) -> tuple[float, float, float]:
    """The N, E, D position variances of a VISION_POSITION_ESTIMATE or ODOMETRY (NaN when
    the message carries none)."""
    cov = list(f["pose_covariance"] if name == "ODOMETRY" else f["covariance"])
    if len(cov) < 12:
        return math.nan, math.nan, math.nan
    return float(cov[0]), float(cov[6]), float(cov[11])


def judge_landing_target(profile: Profile, f: Mapping[str, Any]) -> tuple[bool, str]:
    """ArduPilot: frame BODY_FRD or LOCAL_FRD ("Plnd: Frame not supported" otherwise) and, with
    position_valid, distance > 0.  PX4: position_valid = 1 needs LOCAL_NED."""
    values = [f["angle_x"], f["angle_y"], f["distance"], f["x"], f["y"], f["z"]]
    if not all(math.isfinite(float(v)) for v in values):
        return False, "non_finite"
    if profile == "ardupilot":
        if f["frame"] not in (MAV_FRAME_BODY_FRD, MAV_FRAME_LOCAL_FRD):
            return False, "frame_not_supported"
        if f["position_valid"] and f["distance"] <= 0:
            return False, "distance_not_positive"
        return True, "accepted"
    if f["position_valid"] != 1:
        return True, "accepted_as_irlock_report"
    if f["frame"] != 1:
        return False, "position_valid_needs_local_ned"
    return True, "accepted"
