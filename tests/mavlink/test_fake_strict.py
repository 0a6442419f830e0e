"""The strict fake autopilot's parts, without a link: streams, estimator, failsafe."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig, cm_s
from mavlink_bridge.fake_ekf import (
    EKF_FLAGS_HEALTHY,
    EKF_FLAGS_NO_HORIZ,
    AttitudeModel,
    EstimatorConfig,
    FakeEstimator,
    estimator_defaults,
    fix_variances,
)
from mavlink_bridge.fake_rules import JitterCorrection
from mavlink_bridge.fake_streams import MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED, FakeStreams
from mavlink_bridge.fake_vehicle import (
    ARDUCOPTER_GUIDED,
    ARDUCOPTER_LAND,
    PX4_LAND,
    FlightState,
    GuidedVehicle,
)
from mavlink_bridge.streams import MESSAGE_IDS

PERIODS = (("HEARTBEAT", 1.0), ("ATTITUDE", 0.05), ("TIMESYNC", 0.1), ("DISTANCE_SENSOR", 0.1))
SENDABLE = frozenset({"HEARTBEAT", "ATTITUDE", "TIMESYNC", "DISTANCE_SENSOR"})


def sent(streams: FakeStreams, seconds: float, step_s: float = 0.01) -> dict[str, int]:
    out: dict[str, int] = {}
    for k in range(round(seconds / step_s)):
        for name in streams.due(k * step_s):
            out[name] = out.get(name, 0) + 1
    return out


def test_strict_streams_only_heartbeat_until_asked_and_a_reboot_forgets() -> None:
    s = FakeStreams("strict", "ardupilot", PERIODS, SENDABLE)
    assert sent(s, 2.0) == {"HEARTBEAT": 2}
    assert s.set_interval(MESSAGE_IDS["ATTITUDE"], 100_000) == MAV_RESULT_ACCEPTED
    assert sent(s, 1.0)["ATTITUDE"] in (9, 10)  # on a 10 ms loop, like the real fake
    assert s.set_interval(MESSAGE_IDS["ATTITUDE"], 0) == MAV_RESULT_ACCEPTED  # default 20 Hz
    assert sent(s, 1.0)["ATTITUDE"] in (19, 20)
    assert s.set_interval(MESSAGE_IDS["ATTITUDE"], -1) == MAV_RESULT_ACCEPTED  # stop
    assert "ATTITUDE" not in sent(s, 1.0)
    assert s.set_interval(MESSAGE_IDS["LOCAL_POSITION_NED"], 1e5) == MAV_RESULT_FAILED
    assert s.request_once(MESSAGE_IDS["ATTITUDE"]) == MAV_RESULT_ACCEPTED
    assert sent(s, 1.0).get("ATTITUDE") == 1
    s.set_interval(MESSAGE_IDS["ATTITUDE"], 100_000)
    s.reset()
    assert sent(s, 1.0) == {"HEARTBEAT": 1}


def test_px4_sends_timesync_unasked_and_absent_sensors_nothing() -> None:
    s = FakeStreams("strict", "px4", PERIODS, SENDABLE, absent=("DISTANCE_SENSOR",))
    assert sent(s, 1.0) == {"HEARTBEAT": 1, "TIMESYNC": 10}
    assert s.set_interval(MESSAGE_IDS["DISTANCE_SENSOR"], 50_000) == MAV_RESULT_ACCEPTED
    assert "DISTANCE_SENSOR" not in sent(s, 1.0)
    assert sent(FakeStreams("all", "ardupilot", PERIODS, SENDABLE), 1.0)["ATTITUDE"] in (19, 20)


def hover_estimator(config: EstimatorConfig | None = None) -> FakeEstimator:
    """Initialised at (0, 0, -5) after 2 s of fixes at the truth, hovering."""
    ekf = FakeEstimator(config or EstimatorConfig(accel_bias_m_s2=0.0))
    for k in range(200):
        t = k * 0.01
        ekf.predict(t, np.zeros(3))
        ekf.observe_baro(t, -5.0)
        if k % 5 == 0:
            assert ekf.fuse(t, (0.0, 0.0, -5.0), (0.01, 0.01, 0.01)).accepted
    return ekf


def test_the_gate_is_against_its_own_estimate_never_the_truth() -> None:
    """The estimate has drifted 3 m; a fix at the truth is 3 m from it and rejected, a fix
    next to the (wrong) estimate is fused: exactly what a real EKF does."""
    ekf = hover_estimator()
    ekf.x[0, 0] += 3.0  # the estimate is 3 m north of the truth (0, 0, -5)
    for k in range(1, 11):
        ekf.predict(2.0 + k * 0.01, np.zeros(3))
    ekf.P[0] = np.diag([0.01, 0.01])
    truth_fix = ekf.fuse(2.1, (0.0, 0.0, -5.0), (0.01, 0.01, 0.01))
    assert (truth_fix.accepted, truth_fix.reason) == (False, "innovation_gate")
    assert truth_fix.innovation_m == pytest.approx(3.0, abs=0.01)
    near_estimate = ekf.fuse(2.1, (3.05, 0.0, -5.0), (0.01, 0.01, 0.01))
    assert near_estimate.accepted


def test_noise_floor_and_delay_follow_the_profile() -> None:
    assert estimator_defaults("ardupilot").delay_ms == 10.0  # VISO_DELAY_MS
    assert estimator_defaults("ardupilot").noise_floor_m == 0.2  # VISO_POS_M_NSE
    assert estimator_defaults("px4").delay_ms == 0.0  # EKF2_EV_DELAY
    assert estimator_defaults("px4").noise_floor_m == 0.1  # EKF2_EVP_NOISE
    # a 0.8 m innovation north with a tiny P: EKF3's (nuN^2 + nuE^2) / (S_N + S_E) is 31.7
    # with a 0.1 m floor (over 5^2), 8.0 with 0.2 m
    for floor, accepted in ((0.1, False), (0.2, True)):
        ekf = hover_estimator(EstimatorConfig(accel_bias_m_s2=0.0, noise_floor_m=floor))
        ekf.P[:, 0, 0] = 1e-4
        assert ekf.fuse(2.0, (0.8, 0.0, -5.0), (1e-6, 1e-6, 1e-6)).accepted is accepted
    # EKF3 sums both axes: 0.6 m north with S 0.0101 per axis passes (17.8), where the per-axis
    # sum PX4's reading takes (35.6) rejects it
    for model, accepted in (("ardupilot", True), ("px4", False)):
        ekf = hover_estimator(EstimatorConfig(accel_bias_m_s2=0.0, noise_floor_m=0.1,
                                              noise_model=model))  # type: ignore[arg-type]
        ekf.P[:, 0, 0] = 1e-4
        assert ekf.fuse(2.0, (0.6, 0.0, -5.0), (1e-6, 1e-6, 1e-6)).accepted is accepted


def test_ardupilot_fuses_one_error_on_every_axis_px4_one_per_axis() -> None:
    """ArduPilot: posErr = cbrt(c0^2 + c6^2 + c11^2) (0 for a NaN c0) in [VISO_POS_M_NSE,
    100], fused at most 10 m on north, east and down alike; PX4: each variance at least
    EKF2_EVP_NOISE^2 (../shared/MAVLINK.md; fake_ekf.fix_variances has the sources)."""
    weak_east = (0.01, 9.0, 0.01)  # 0.1 m north, 3 m east
    assert fix_variances(weak_east, 0.2, "ardupilot") == pytest.approx(
        [math.cbrt(1e-4 + 81.0 + 1e-4) ** 2] * 3)  # 4.33 m on every axis
    assert fix_variances(weak_east, 0.1, "px4") == pytest.approx(list(weak_east))
    assert fix_variances((1e-4, 1e-4, 1e-4), 0.2, "ardupilot") == pytest.approx([0.04] * 3)
    assert fix_variances((1e-4, 1e-4, 1e-4), 0.1, "px4") == pytest.approx([0.01] * 3)
    assert fix_variances((math.nan, 4.0, 4.0), 0.2, "ardupilot") == pytest.approx([0.04] * 3)
    for huge in ((1e6, 1e6, 1e6), (math.inf, 1.0, 1.0), (1e200, 1.0, 1.0), (1.0, math.nan, 1.0)):
        assert fix_variances(huge, 0.2, "ardupilot") == pytest.approx([100.0] * 3)  # 10 m
    assert fix_variances((0.0, 0.0, 0.0), 0.001, "ardupilot") == pytest.approx(
        [1e-4, 1e-4, 0.01])  # EKF3's own floors: 0.01 m across, 0.1 m down
    assert estimator_defaults("ardupilot").noise_model == "ardupilot"
    assert estimator_defaults("px4").noise_model == "px4"
    # a fix 0.3 m north, sure of north but not of east: PX4 follows it north, ArduPilot
    # hardly moves (its one error is the east's)
    moved = {}
    for profile in ("ardupilot", "px4"):
        ekf = hover_estimator(dataclasses.replace(estimator_defaults(profile),
                                                  accel_bias_m_s2=0.0))
        before = ekf.position()[0]
        assert ekf.fuse(2.0, (0.3, 0.0, -5.0), weak_east).accepted
        moved[profile] = ekf.position()[0] - before
    assert moved["px4"] > 0.03 and 0.0 < moved["ardupilot"] < 0.001, moved


def test_flags_drop_6s_into_an_outage() -> None:
    ekf = hover_estimator()
    last = ekf.last_fused_s
    assert last is not None
    assert ekf.flags(last, origin_set=True) == EKF_FLAGS_HEALTHY == 0x33F
    assert ekf.flags(last + 5.99, origin_set=True) == EKF_FLAGS_HEALTHY
    assert ekf.flags(last + 6.01, origin_set=True) == EKF_FLAGS_NO_HORIZ == 0x25


@pytest.mark.parametrize(("profile", "land", "texts"), [
    ("ardupilot", ARDUCOPTER_LAND, ["VisOdom: not healthy", "EKF variance",
                                    "EKF Failsafe: changed to LAND Mode"]),
    ("px4", PX4_LAND, ["Failsafe activated: switching to Land"])])
def test_ekf_failsafe_lands_one_second_after_the_position_goes(
        profile: str, land: int, texts: list[str]) -> None:
    said: list[str] = []
    f = FlightState(profile, armed=True, custom_mode=ARDUCOPTER_GUIDED)
    f.check_ekf(10.0, False, said.append)
    f.check_ekf(10.9, False, said.append)
    assert f.failsafe is None and f.custom_mode == ARDUCOPTER_GUIDED
    f.check_ekf(11.0, False, said.append)
    assert f.failsafe == "ekf" and f.custom_mode == land and f.landing
    assert said == texts
    assert f.heartbeat() == (0x81, land, 5)  # armed, custom; MAV_STATE_CRITICAL
    assert f.set_mode(11.5, ARDUCOPTER_GUIDED, 0) == 4  # no position mode in failsafe


def test_arming_without_a_position_is_refused_like_ardupilot() -> None:
    said: list[str] = []
    f = FlightState("ardupilot")
    assert f.arm(0.0, True, position_ok=False, text=said.append) == 4
    assert said == ["PreArm: VisOdom: not healthy"] and not f.armed
    assert f.arm(1.0, True, position_ok=True, text=said.append) == 0 and f.armed


def test_coupled_attitude_follows_the_fixes() -> None:
    """A fix steadily 0.3 m north of the estimate pulls the tilt (coupled) and not at all
    otherwise; the yaw drifts at the configured rate."""
    tilts = []
    for coupled in (False, True):
        model = AttitudeModel(yaw_drift_deg_min=2.0, coupled=coupled)
        ekf = hover_estimator(EstimatorConfig(accel_bias_m_s2=0.0, attitude=model))
        for k in range(100):
            ekf.fuse(2.0 + k * 0.03, (ekf.position()[0] + 0.3, 0.0, -5.0), (0.04,) * 3)
        tilts.append(ekf.tilt_err.copy())
        assert math.degrees(ekf.yaw_err) == pytest.approx(2.0 * 2.0 / 60.0, rel=0.05)
    assert np.allclose(tilts[0], 0.0)
    # tE decreases (a fix north says "accelerating north"); tN barely moves
    assert tilts[1][1] < -0.03 and abs(tilts[1][0]) < 0.1 * abs(tilts[1][1])


def test_guided_vehicle_takes_off_flies_to_a_target_and_lands() -> None:
    v = GuidedVehicle((0.0, 0.0, 0.0), math.radians(90.0))
    v.takeoff(4.0)
    v.step_to(8.0)
    assert v(8.0).position_ned_m[2] == pytest.approx(-4.0, abs=0.05)
    v.goto((6.0, 0.0, -4.0), math.radians(90.0))
    v.step_to(16.0)
    assert v(16.0).position_ned_m[0] == pytest.approx(6.0, abs=0.05)
    v.landing = True
    v.step_to(30.0)
    assert v.on_ground()


def test_a_runaway_velocity_is_sent_held_to_its_field() -> None:
    """GLOBAL_POSITION_INT's velocities are int16 cm/s: an estimate that ran away (400 m/s
    in a coupled flight trusting its own fixes) is sent at the field's limit, not a
    struct.error that stops the fake's streams."""
    assert [cm_s(v) for v in (1.234, -0.5, 400.0, -400.0)] == [123, -50, 32767, -32768]


def test_ardupilot_places_a_late_fix_by_the_quickest_link_lag() -> None:
    """ArduPilot's jitter correction (AP_Common/JitterCorrection.cpp): a fix that took 150 ms
    longer than the quickest is aged 150 ms, whatever the two clocks' offset; one more than
    500 ms behind is held at 500 ms; the smallest lag of each 100 samples becomes the
    offset, so the link settles after a slow start."""
    jc = JitterCorrection()
    offset_us = 7_000_000_000  # the companion's clock is far from the autopilot's
    ages = [jc.age_ms(t, t + offset_us + lag) for t, lag in
            ((0, 40_000), (33_000, 190_000), (66_000, 60_000), (99_000, 40_000))]
    assert ages == pytest.approx([0.0, 150.0, 20.0, 0.0])
    assert jc.age_ms(132_000, 132_000 + offset_us + 900_000) == pytest.approx(500.0)
    # a link that got slower (clock drift): the old least lag holds for the window it is
    # in and the next one; then that window's least lag is the offset
    drift = JitterCorrection(convergence_loops=3)
    lags_ms = [20, 80, 80, 80, 80, 80, 80]
    assert [drift.age_ms(k * 1000, k * 1000 + offset_us + lag * 1000)
            for k, lag in enumerate(lags_ms)] == pytest.approx([0, 60, 60, 60, 60, 60, 0])


def test_the_ardupilot_fake_ages_a_late_fix_and_a_reboot_forgets_the_link() -> None:
    """The fake's ArduPilot takes a vision stamp through that correction (it used to take
    every fix as made at its arrival); a reboot starts the link's offset anew."""
    now_ns = [10_000_000_000]
    ap = FakeAutopilot(FakeAutopilotConfig(profile="ardupilot"), clock_ns=lambda: now_ns[0])
    remote_us = 123_456_789  # the companion's clock

    def fix_after(lag_ms: int) -> float:
        now_ns[0] += 33_000_000
        return ap._stamp_age_ms(remote_us + now_ns[0] // 1000 - lag_ms * 1000)

    assert [fix_after(lag) for lag in (50, 50, 200, 60)] == pytest.approx([0, 0, 150, 10])
    ap.reboot(0.0)
    assert fix_after(200) == pytest.approx(0.0)


def flying_estimator(config: EstimatorConfig) -> FakeEstimator:
    """Flying north at a steady 2 m/s from (0, 0, -5), its fixes at the truth."""
    ekf = FakeEstimator(config)
    ekf.initialised = ekf.height_initialised = True
    ekf.x[:] = ((0.0, 2.0), (0.0, 0.0), (-5.0, 0.0))
    for k in range(301):
        ekf.predict(k * 0.01, np.zeros(3))
    return ekf


def test_ardupilot_compares_a_late_fix_at_its_fusion_horizon_not_at_its_stamp() -> None:
    """EKF3's writeExtNavData moves a stamp older than its delayed horizon (60 ms behind
    with the default delays) up to it: a fix made 200 ms before it arrives, at the truth of
    its stamp, is compared with where the estimate was 60 ms ago, 2 m/s x (200 - 60) ms off.
    With VISO_DELAY_MS at the fix's latency, 200 ms, the horizon is 200 ms behind and the
    stamp less 206 ms is moved up to it: the fix is compared at its stamp (what `autopilot
    setup`'s VISO_DELAY_MS from the measured latency is for).  PX4's horizon is not
    modelled: compared at the stamp less EKF2_EV_DELAY (0)."""
    stamp_s, arrival_s = 2.8, 3.0  # the estimate moves 2 m/s x 10 ms between samples
    for config, at_s in ((estimator_defaults("ardupilot"), 2.94),
                         (dataclasses.replace(estimator_defaults("ardupilot"),
                                              delay_ms=200.0), 2.8),
                         (estimator_defaults("px4"), 2.8)):
        ekf = flying_estimator(dataclasses.replace(config, accel_bias_m_s2=0.0,
                                                   accel_noise_m_s2_rthz=0.0))
        assert ekf.measured_at(stamp_s, arrival_s) == pytest.approx(at_s)
        truth_north = 2.0 * stamp_s
        verdict = ekf.fuse(stamp_s, (truth_north, 0.0, -5.0), (0.01,) * 3, now_s=arrival_s)
        assert verdict.innovation_m == pytest.approx(2.0 * abs(stamp_s - at_s), abs=0.021)
    # a fix younger than the horizon keeps its stamp (less VISO_DELAY_MS and 6 ms)
    ekf = flying_estimator(dataclasses.replace(estimator_defaults("ardupilot")))
    assert ekf.measured_at(2.98, 3.0) == pytest.approx(2.964)


def test_a_new_viso_delay_widens_ekf3s_horizon_only_from_the_next_boot() -> None:
    """setup_core sizes the horizon when the EKF starts: VISO_DELAY_MS 200 set in flight
    moves the stamp back at once but the horizon stays 60 ms until a reboot."""
    ekf = FakeEstimator(estimator_defaults("ardupilot"))
    ekf.set_parameter("VISO_DELAY_MS", 200.0)
    assert ekf.measured_at(2.8, 3.0) == pytest.approx(2.94)  # the horizon, 60 ms back
    ekf.set_parameter("VISO_DELAY_MS", 200.0, at_boot=True)
    assert ekf.measured_at(2.8, 3.0) == pytest.approx(2.8)
    now_ns = [10_000_000_000]
    ap = FakeAutopilot(FakeAutopilotConfig(profile="ardupilot"), clock_ns=lambda: now_ns[0])
    ap.ekf.set_parameter("VISO_DELAY_MS", 200.0)
    ap.params.sets.append(("VISO_DELAY_MS", 200.0))  # as a PARAM_SET stores it
    ap.params.values["VISO_DELAY_MS"] = 200.0
    assert ap.ekf.horizon_delay_ms == 10.0
    ap.reboot(0.0)
    assert ap.ekf.horizon_delay_ms == 200.0


def test_the_fake_hands_its_estimator_a_fixs_stamp_and_its_arrival() -> None:
    """The horizon needs both: ``_fuse`` gives the estimator the stamp's time (arrival less
    the jitter-corrected age) and the arrival itself (``now_s``)."""
    now_ns = [10_000_000_000]
    ap = FakeAutopilot(FakeAutopilotConfig(profile="ardupilot"), clock_ns=lambda: now_ns[0])
    seen: dict[str, object] = {}

    def fuse(t_s: float, *_args: object, now_s: float | None = None) -> object:
        seen.update(t_s=t_s, now_s=now_s)
        return ap.ekf.__class__.fuse(ap.ekf, t_s, *_args, now_s=now_s)  # type: ignore[arg-type]

    ap.judge.screen = lambda *_a: (None, False)  # type: ignore[method-assign]
    ap.ekf.fuse = fuse  # type: ignore[method-assign]
    ap._fuse("VISION_POSITION_ESTIMATE", {"covariance": [0.01] * 21}, (0.0, 0.0, -4.0), 150.0)
    assert seen["now_s"] == pytest.approx(ap.flight_s())
    assert seen["t_s"] == pytest.approx(ap.flight_s() - 0.150)
