"""The simulated laser range finder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.sim.rangefinder import RangeFinder, RangeFinderConfig
from companion.sim.trajectory import KinematicState
from companion.sim.world import World


def state(yaw_deg: float = 90.0, pitch_deg: float = 0.0, north: float = 0.0) -> KinematicState:
    att = (0.0, math.radians(pitch_deg), math.radians(yaw_deg))
    return KinematicState(0.0, (north, 0.0, -4.0), (0, 0, 0), att)


def test_down_beam_measures_height_and_tilt(one_landmark_world: World) -> None:
    rf = RangeFinder(RangeFinderConfig(), one_landmark_world)
    assert rf.true_range(state()) == pytest.approx(4.0)
    # pitched 30 degrees, the down beam is slanted: 4 / cos 30
    assert rf.true_range(state(pitch_deg=30.0)) == pytest.approx(4.0 / math.cos(math.radians(30)))


def test_forward_beam_hits_the_landmark_or_nothing(one_landmark_world: World) -> None:
    rf = RangeFinder(RangeFinderConfig(axis_body=(1.0, 0.0, 0.0)), one_landmark_world)
    assert rf.true_range(state()) == pytest.approx(10.0)  # facing east at the plate
    assert rf.true_range(state(north=5.0)) is None  # beside it: no wall, no ground ahead


def test_noise_dropouts_and_limits(one_landmark_world: World) -> None:
    cfg = RangeFinderConfig(noise_m=0.05, dropout_prob=0.2)
    rf = RangeFinder(cfg, one_landmark_world)
    rng = np.random.default_rng(1)
    got = [rf.measure(state(), rng) for _ in range(2000)]
    values = np.array([g for g in got if g is not None])
    assert 0.15 < 1 - len(values) / len(got) < 0.25
    assert abs(values.mean() - 4.0) < 0.01 and 0.04 < values.std() < 0.06
    short = RangeFinder(RangeFinderConfig(max_range_m=3.0, dropout_prob=0.0), one_landmark_world)
    assert short.measure(state(), rng) is None
