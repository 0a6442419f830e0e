"""The strict fake's height: from its barometer unless its parameters make the fixes the
height source (mavlink_bridge/fake_baro.py)."""

from __future__ import annotations

import numpy as np
import pytest

from mavlink_bridge.fake_baro import BaroConfig, SimBarometer, height_source
from mavlink_bridge.fake_ekf import EstimatorConfig, FakeEstimator
from mavlink_bridge.params import autopilot_defaults, profile_parameters

TRUE_DOWN = -4.0  # hovering 4 m above the boot point


def hover(source: str, seconds: float, fix_down: float | None = None, t0: float = 0.0,
          ekf: FakeEstimator | None = None) -> FakeEstimator:
    """``seconds`` of hover at (0, 0, TRUE_DOWN); a fix every 0.05 s whose down is
    ``fix_down`` (None: no fixes)."""
    if ekf is None:
        ekf = FakeEstimator(EstimatorConfig(accel_bias_m_s2=0.0, height_source=source))  # type: ignore[arg-type]
    for k in range(round(seconds / 0.01)):
        t = t0 + k * 0.01
        ekf.predict(t, np.zeros(3))
        ekf.observe_baro(t, TRUE_DOWN)
        if fix_down is not None and k % 5 == 0:
            ekf.fuse(t, (0.0, 0.0, fix_down), (0.01, 0.01, 0.01))
    return ekf


def test_the_height_comes_from_the_barometer_before_any_fix() -> None:
    """EKF3 sets its height from the barometer at start: a vehicle taken off by hand
    reports its height before the first fix (the old fake reported 0 until then)."""
    ekf = hover("baro", 1.0)
    assert not ekf.initialised and ekf.height_initialised
    assert ekf.position()[2] == pytest.approx(TRUE_DOWN, abs=0.3)
    old = hover("fixes", 1.0)
    assert old.position()[2] == 0.0 and not old.height_initialised


def test_with_baro_height_the_fixes_down_is_not_fused() -> None:
    """Fixes 1 m low for 10 s: the baro-height estimate stays at the truth; with ExtNav
    height (or the old fake) it follows the fixes."""
    assert hover("baro", 10.0, fix_down=TRUE_DOWN + 1.0).position()[2] == pytest.approx(
        TRUE_DOWN, abs=0.3)
    for source in ("extnav", "fixes"):
        assert hover(source, 10.0, fix_down=TRUE_DOWN + 1.0).position()[2] == pytest.approx(
            TRUE_DOWN + 1.0, abs=0.05)


def test_extnav_height_falls_back_to_the_barometer_without_a_jump() -> None:
    """ExtNav height 1 m off the barometer; the fixes stop: after 0.5 s the barometer
    (with the offset EKF3 keeps) holds the height where the fixes left it; when they return
    the height is reset to theirs."""
    ekf = hover("extnav", 5.0, fix_down=TRUE_DOWN + 1.0)
    ekf = hover("extnav", 5.0, t0=5.0, ekf=ekf)  # no fixes
    assert ekf.position()[2] == pytest.approx(TRUE_DOWN + 1.0, abs=0.15)
    ekf = hover("extnav", 0.1, fix_down=TRUE_DOWN + 0.5, t0=10.0, ekf=ekf)
    assert ekf.position()[2] == pytest.approx(TRUE_DOWN + 0.5, abs=0.05)


def test_the_simulated_barometer_noise_and_drift() -> None:
    baro = SimBarometer(BaroConfig(), seed=3)
    t = np.arange(0.0, 120.0, 0.05)
    h = np.array([baro.read(float(v), TRUE_DOWN) for v in t])
    err = h - (-TRUE_DOWN) - baro.drift_rate_m_s * t
    assert float(np.std(err)) == pytest.approx(0.2, rel=0.1)  # SIM_BARO_RND
    assert abs(float(np.mean(err))) < 0.02
    rates = [SimBarometer(BaroConfig(), seed=s).drift_rate_m_s for s in range(200)]
    assert float(np.std(rates)) == pytest.approx(0.001, rel=0.2)
    assert baro.due(120.0)  # 20 Hz: due 0.05 s after the last reading, not before
    baro.read(120.0, TRUE_DOWN)
    assert not baro.due(120.04) and baro.due(120.05)


@pytest.mark.parametrize(("profile", "values", "source"), [
    ("ardupilot", autopilot_defaults("ardupilot"), "baro"),
    ("ardupilot", profile_parameters("ardupilot"), "baro"),  # the profile keeps the baro
    ("ardupilot", {"EK3_SRC1_POSZ": 6.0}, "extnav"),
    ("px4", autopilot_defaults("px4"), "baro"),
    ("px4", profile_parameters("px4"), "baro"),
    ("px4", {"EKF2_EV_CTRL": 3.0}, "extnav"),
])
def test_the_height_source_follows_the_parameters(
        profile: str, values: dict[str, float], source: str) -> None:
    assert height_source(profile, values) == source
