"""companion.fixgate: a fix too vague for its distance is held back (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.autopilot import vision_fix
from companion.fixgate import FixGate, FixGateConfig
from tracker.pose.types import PoseFix


def fix(sigma_m: float) -> PoseFix:
    cov = np.diag([sigma_m**2 / 3] * 3 + [1e-4] * 3)
    return PoseFix(0, (0.0, 0.0, -17.0), (0.0, 0.0, 0.0), cov, 80, ("a",), "pnp")


def test_a_fix_whose_sigma_exceeds_its_share_of_the_distance_is_not_precise() -> None:
    gate = FixGate(FixGateConfig(max_sigma_rel=0.05))
    assert gate.precise(fix(0.9), 20.0)  # 4.5 % of 20 m
    assert not gate.precise(fix(1.1), 20.0)  # 5.5 %
    assert not gate.precise(fix(0.1), 0.0)  # no distance: nothing is precise enough


def test_the_vagueness_check_is_off_by_default() -> None:
    assert FixGate().precise(fix(100.0), 1.0)


def echoing(t_s: float, east_m: float, sigma_m: float = 4.0) -> PoseFix:
    """A fix whose whole covariance is the autopilot's part (the (6, 6) hover's
    ``altitude_bearing``: the range from the height prior), at ``t_s``."""
    cov = np.diag([1.0, sigma_m**2, 0.25, 1e-4, 1e-4, 1e-4])
    return PoseFix(round(t_s * 1e6), (6.0, east_m, -4.0), (0.0, 0.0, 0.0), cov, 10,
                   ("wall-02",), "altitude_bearing", echo_covariance=cov.copy())


def test_a_stream_is_stated_as_one_fix_per_correlation_time() -> None:
    gate = FixGate(FixGateConfig(echo_correlation_s=20.0))
    assert gate.stated(echoing(0.0, 6.0)).sent_covariance is None  # the first: as solved
    at_30_hz = gate.stated(echoing(1 / 30, 6.0))  # 600 fixes per 20 s
    assert at_30_hz.sent_covariance is not None
    np.testing.assert_allclose(at_30_hz.sent_covariance,
                               600.0 * echoing(0.0, 6.0).covariance, rtol=1e-4)
    np.testing.assert_array_equal(at_30_hz.covariance, echoing(0.0, 6.0).covariance)  # own
    assert "x 600" in at_30_hz.notes[-1]
    assert gate.stated(echoing(30.0, 6.0)).sent_covariance is None  # after a longer pause


def test_only_the_autopilots_part_is_inflated() -> None:
    gate = FixGate(FixGateConfig(echo_correlation_s=1.0))
    gate.stated(fix(0.3))
    own = fix(0.3)
    half = PoseFix(100_000, own.position_ned_m, own.attitude_rpy_rad, own.covariance, 80,
                   ("a",), "pnp", echo_covariance=0.5 * own.covariance)
    stated = gate.stated(half)  # 0.1 s after the last: 10 per correlation time
    assert stated.sent_covariance is not None
    np.testing.assert_allclose(stated.sent_covariance,
                               own.covariance + 9 * 0.5 * own.covariance)
    assert gate.stated(fix(0.3)).sent_covariance is None  # no autopilot part: as solved


def test_the_statement_is_off_by_default() -> None:
    gate = FixGate()
    gate.stated(echoing(0.0, 6.0))
    assert gate.stated(echoing(1 / 30, 6.0)).sent_covariance is None


def test_an_autopilot_does_not_follow_a_biased_stream_stated_so() -> None:
    """The strict fake's EKF (EK3_ACC_P_NSE 0.35, R from the covariance), converged on good
    fixes, then 4 s of the (6, 6) hover's fixes at 30 Hz, all 3 m east of the truth with a
    stated 4 m (each one honest alone): stated as solved, it follows them (the flight's
    1.7-3.5 m); stated as correlated, PX4's rule (the variances as sent) stays within its
    dead reckoning's error -- but ArduPilot's does not: it fuses no fix at more than 10 m
    (EKF3 ``constrain(posErr, 0.01, 10)``), so 30 such fixes a second still drag it most of
    the way (docs/decisions.md, "ArduPilot fuses no fix at more than 10 m").  Told that cap
    (the ArduPilot profile's ``fixgate.fused_error_cap_m``), the gate sends each such fix
    moved towards the autopilot's estimate, and ArduPilot stays as PX4 does ("A fix
    ArduPilot cannot weigh is sent as its pull")."""
    from mavlink_bridge.fake_ekf import EstimatorConfig, FakeEstimator

    def hover(gate: FixGate, model: str) -> float:
        ekf = FakeEstimator(EstimatorConfig(accel_bias_m_s2=0.0, noise_model=model),  # type: ignore[arg-type]
                            seed=0)
        t = 0.0
        ekf.predict(t, np.zeros(3))
        for _ in range(300):  # 10 s of two-plate fixes: 1 cm
            t += 1 / 30
            ekf.predict(t, np.zeros(3))
            ekf.fuse(t, (6.0, 6.0, -4.0), (1e-4, 1e-4, 1e-4))
        for _ in range(120):
            t += 1 / 30
            ekf.predict(t, np.zeros(3))
            # what the bridge sends; the autopilot's estimate as LOCAL_POSITION_NED says
            sent = vision_fix(gate.stated(echoing(t, 9.0), ekf.position()), 0)
            cov = np.zeros((6, 6))
            cov[np.triu_indices(6)] = sent.covariance
            assert ekf.fuse(t, sent.position_ned_m, (cov[0, 0], cov[1, 1], cov[2, 2])).accepted
        return abs(ekf.position()[1] - 6.0)

    stated = FixGateConfig(echo_correlation_s=20.0)
    assert hover(FixGate(), "px4") > 2.0 and hover(FixGate(), "ardupilot") > 2.0
    assert hover(FixGate(stated), "px4") < 0.3
    assert hover(FixGate(stated), "ardupilot") > 2.0
    capped = FixGateConfig(echo_correlation_s=20.0, fused_error_cap_m=10.0)
    assert hover(FixGate(capped), "ardupilot") < 0.3
    assert hover(FixGate(capped), "px4") < 0.3  # (the PX4 profile leaves the cap at 0)


def test_a_fix_stated_worse_than_the_cap_is_sent_as_its_pull() -> None:
    """Stated 40 m (1600 m^2) with a 10 m cap: sent at 100 / 1600 of its offset from the
    autopilot's estimate, its own position and covariance kept; a fix within the cap, or
    without the autopilot's estimate, is sent as it is."""
    gate = FixGate(FixGateConfig(fused_error_cap_m=10.0))
    vague = fix(40.0 * 3**0.5)  # 40 m on each axis
    sent = gate.stated(vague, (1.0, 2.0, -17.0))
    assert sent.sent_position_ned_m == pytest.approx((1.0 - 1.0 / 16, 2.0 - 2.0 / 16, -17.0))
    assert sent.position_ned_m == vague.position_ned_m
    np.testing.assert_array_equal(sent.covariance, vague.covariance)
    assert vision_fix(sent, 0).position_ned_m == pytest.approx(sent.sent_position_ned_m)
    assert "sent at 0.0625 of its offset" in sent.notes[-1]
    assert gate.stated(fix(9.0 * 3**0.5), (1.0, 2.0, -17.0)).sent_position_ned_m is None
    assert gate.stated(vague).sent_position_ned_m is None
    assert FixGate().stated(vague, (1.0, 2.0, -17.0)).sent_position_ned_m is None  # off
