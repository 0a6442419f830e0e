"""The fake autopilot's attitude error: a slowly varying Gauss-Markov process on ATTITUDE."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavlink_bridge.fake_autopilot import FakeAutopilot
from mavlink_bridge.fake_drift import AttitudeDrift, AttitudeErrorConfig
from mavlink_bridge.telemetry import Attitude, SimTruth
from mavlink_bridge.vehicle import VehicleState

from .conftest import ASKED, FAST_PERIODS, bridge_config, fake_config, wait_for


def test_error_has_the_stated_sigma_and_correlation_time() -> None:
    """Over 40 correlation times the error's spread is the configured sigma per axis, its
    autocorrelation at one correlation time is exp(-1), and it is continuous (a frame
    later it has barely moved, unlike white noise)."""
    cfg = AttitudeErrorConfig(roll_pitch_sigma_deg=0.2, yaw_sigma_deg=1.0, correlation_s=5.0,
                              yaw_correlation_s=5.0, yaw_drift_deg_min=0.0)
    drift = AttitudeDrift(cfg, seed=3)
    t = np.arange(0.0, 4000.0, 0.5)
    e = np.degrees(np.array([drift.error(float(x)) for x in t]))
    assert np.std(e, axis=0) == pytest.approx([0.2, 0.2, 1.0], rel=0.1)
    lag = int(cfg.correlation_s / 0.5)
    for axis in range(3):
        r = np.corrcoef(e[:-lag, axis], e[lag:, axis])[0, 1]
        assert r == pytest.approx(math.exp(-1.0), abs=0.08)
    step = np.degrees(np.array([drift.error(10.0 + 1 / 30)])) - e[20]
    assert np.all(np.abs(step) < 0.05 * np.array([0.2, 0.2, 1.0]) * 3)


def test_error_is_a_function_of_time_and_seed() -> None:
    cfg = AttitudeErrorConfig()
    a, b = AttitudeDrift(cfg, seed=1), AttitudeDrift(cfg, seed=1)
    late = a.error(30.0)
    assert a.error(2.0) == b.error(2.0)  # b asked in another order
    assert b.error(30.0) == late and a.error(30.0) == late
    assert AttitudeDrift(cfg, seed=2).error(30.0) != late
    none = AttitudeDrift(AttitudeErrorConfig(roll_pitch_sigma_deg=0.0, yaw_sigma_deg=0.0,
                                             yaw_drift_deg_min=0.0))
    assert none.error(12.0) == (0.0, 0.0, 0.0)


def test_the_default_is_a_real_ekfs_error_with_a_slow_yaw_drift() -> None:
    """The fake autopilot's default attitude is not exact: 1 deg roll/pitch, 3 deg yaw
    (stationary, slow) plus 1 deg/min of yaw drift -- what the harness and the demo state."""
    from mavlink_bridge.fake_autopilot import FakeAutopilotConfig

    cfg = FakeAutopilotConfig().attitude_error
    assert cfg is not None and FakeAutopilotConfig.permissive().attitude_error is None
    only_drift = AttitudeDrift(AttitudeErrorConfig(roll_pitch_sigma_deg=0.0,
                                                   yaw_sigma_deg=0.0), seed=0)
    assert math.degrees(only_drift.error(300.0)[2]) == pytest.approx(5.0)  # 1 deg/min
    coarse = dataclasses.replace(cfg, step_s=1.0)  # the same process on a 1 s grid
    t = np.arange(0.0, 3600.0, 1.0)
    drifts = [AttitudeDrift(coarse, seed=k) for k in range(6)]
    runs = [np.degrees([d.error(float(x)) for x in t]) for d in drifts]
    wander = np.concatenate([r - np.outer(t, [0.0, 0.0, cfg.yaw_drift_deg_min / 60.0])
                             for r in runs])
    assert np.std(wander, axis=0) == pytest.approx([1.0, 1.0, 3.0], rel=0.2)
    yaw_step = np.abs(np.diff(runs[0][:, 2]))  # a second apart: slow, not white noise
    assert np.percentile(yaw_step, 95) < 1.0
    assert cfg.stated_sigmas_deg(0.0) == (1.0, 3.0)
    assert cfg.stated_sigmas_deg(240.0)[1] == pytest.approx(5.0)  # hypot(3, 4 min drift)


def test_yaw_wraps() -> None:
    drift = AttitudeDrift(AttitudeErrorConfig(yaw_sigma_deg=5.0), seed=0)
    state = VehicleState(4.0, (0.0, 0.0, -5.0), (0.0, 0.0, 0.0), (0.0, 0.0, math.pi), 5.0)
    _, _, yaw = drift.attitude(state)
    assert -math.pi <= yaw <= math.pi
    assert math.remainder(yaw - math.pi - drift.error(4.0)[2], math.tau) == pytest.approx(0.0)


async def test_attitude_stream_carries_the_error_and_truth_streams_do_not() -> None:
    """With ``attitude_error`` set, ATTITUDE is the truth plus the drift at that time; the
    simulator's own truth (SIM_STATE) stays exact."""
    from mavlink_bridge.bridge import PymavlinkBridge

    att = (0.05, -0.02, 1.0)

    def hover(t: float) -> VehicleState:
        return VehicleState(t, (0.0, 0.0, -5.0), (0.0, 0.0, 0.0), att, 5.0)

    cfg = fake_config(attitude_error=AttitudeErrorConfig(yaw_sigma_deg=3.0), seed=7,
                      home=(47.39, 8.54, 400.0), periods_s=(*FAST_PERIODS, ("SIM_STATE", 0.05)))
    async with FakeAutopilot(cfg, truth=hover) as ap:
        assert ap.attitude_drift is not None
        async with PymavlinkBridge(bridge_config(
                ap.local_port, streams=(*ASKED, ("SIM_STATE", 20.0)))) as bridge:
            bridge.report_health("ok")
            assert await wait_for(lambda: bridge.latest("ATTITUDE") is not None)
            item = bridge.latest("ATTITUDE")
            assert item is not None and isinstance(item.value, Attitude)
            sent_s = item.value.time_boot_ms / 1e3 + (ap.boot_ns - ap.start_ns) * 1e-9
            err = ap.attitude_drift.error(sent_s)  # at its flight time, to the millisecond
            got = (item.value.roll_rad, item.value.pitch_rad, item.value.yaw_rad)
            assert abs(got[2] - att[2]) > 1e-4  # it is not the truth ...
            assert np.allclose(np.subtract(got, att), err, atol=2e-4)  # ... but truth + drift
            assert await wait_for(lambda: bridge.latest("SIM_STATE") is not None)
            sim = bridge.latest("SIM_STATE")
            assert sim is not None and isinstance(sim.value, SimTruth)
            assert np.allclose(sim.value.attitude_rpy_rad, att, atol=1e-6)
