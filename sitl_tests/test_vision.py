"""What the camera sees goes wrong: light changes, occlusion, every landmark leaving view.

The truth of every frame (which landmarks are in view, how much of each a scripted occluder
hides, the image brightness) is recorded beside what the companion made of it, so each test
first proves its stimulus happened, then judges the fixes.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math

import numpy as np
import pytest

from companion.settings import Settings
from companion.sim.effects import EffectSpec
from companion.sim.scenario import ScenarioConfig, load_scenario
from sitl_tests.harness import Flight, FrameRecord, compress_effects, sitl_settings

REACQUIRE_S = 2.0


def fix_share(frames: list[FrameRecord], start_s: float, end_s: float) -> float:
    inside = [f for f in frames if start_s <= f.t_s < end_s]
    return sum(f.fix_ned_m is not None for f in inside) / max(len(inside), 1)


def max_fix_gap_s(frames: list[FrameRecord], start_s: float, end_s: float) -> float:
    """Longest stretch of frame time without a fix inside [start_s, end_s]."""
    times = [start_s, *[f.t_s for f in frames if f.fix_ned_m is not None
                        and start_s <= f.t_s <= end_s], end_s]
    return float(max(np.diff(times)))


def brightness(frames: list[FrameRecord], start_s: float, end_s: float) -> float:
    return float(np.mean([f.brightness for f in frames if start_s <= f.t_s < end_s]))


def assert_kept_through_light_change(flight: Flight, start_s: float, end_s: float,
                                     dimmest: float, brightest: float) -> None:
    """``dimmest``: the light must fall to this share of the light before ``start_s``
    (0: no dimming is expected); ``brightest``: rise to this share (0: no rise expected)."""
    frames = flight.frames
    before = brightness(frames, 0.5, start_s)
    lo = min(brightness(frames, t, t + 0.5) for t in np.arange(start_s, end_s - 0.5, 0.25))
    hi = max(brightness(frames, t, t + 0.5) for t in np.arange(start_s, end_s - 0.5, 0.25))
    assert dimmest == 0.0 or lo <= dimmest * before, \
        f"the light never dimmed: {lo:.0f} vs {before:.0f}"
    assert brightest == 0.0 or hi >= brightest * before, \
        f"the light never brightened: {hi:.0f} vs {before:.0f}"
    gap = max_fix_gap_s(frames, start_s, end_s)
    share = fix_share(frames, start_s, end_s)
    assert gap <= 1.0, f"fixes stopped for {gap:.2f} s during the light change"
    assert share >= 0.7, f"only {share:.0%} of frames gave a fix during the light change"
    assert not flight.invented(), flight.invented()[:3]
    assert flight.rmse_m() < 0.5
    accepted = sum(a.accepted for a in flight.fake.arrivals) / len(flight.fake.arrivals)
    assert accepted >= 0.9
    print(f"light {lo / before:.2f}..{hi / before:.2f} of normal: fix share {share:.0%}, "
          f"longest gap {gap:.2f} s, RMSE {flight.rmse_m():.3f} m, accepted {accepted:.0%}")


async def test_illumination_ramp(settings: Settings) -> None:
    """The light fades to 35 % and back (the illumination_ramp scenario, twice as fast):
    fixes continue throughout (no gap over 1 s, >= 70 % of frames), none invented."""
    sc = compress_effects(load_scenario("illumination_ramp"), 0.5)  # 2.5 s .. 12.5 s
    flight = await Flight(sc, 13.5, settings).run()
    assert_kept_through_light_change(flight, 2.5, 12.5, dimmest=0.5, brightest=0.9)


@pytest.fixture(scope="module")
def sudden_light(tmp_path_factory: pytest.TempPathFactory) -> Flight:
    """The sudden_light scenario twice as fast: 40 % at 3 s, 160 % + colour cast at 6 s,
    normal at 9 s."""
    sc = compress_effects(load_scenario("sudden_light"), 0.5)
    settings = sitl_settings(tmp_path_factory.mktemp("sudden_light"))
    return asyncio.run(Flight(sc, 11.0, settings).run())


def test_sudden_light_drop(sudden_light: Flight) -> None:
    """The light drops to 40 % at once: the landmarks are kept through the step."""
    assert_kept_through_light_change(sudden_light, 3.0, 6.0, dimmest=0.5, brightest=0.0)


def test_sudden_light_jump_to_bright(sudden_light: Flight) -> None:
    """The light jumps to 160 % with a colour cast: the landmarks are kept.  (Measured
    against the mean light of 0.5-6 s, which holds the dim phase: the frames' grey level
    goes 51 -> 187 at the jump, 1.5x the normal 127; the old "lo <= 2x that mean" check
    failed on the stimulus itself, 187 against 2 x 90.)"""
    assert_kept_through_light_change(sudden_light, 6.0, 9.0, dimmest=0.0, brightest=1.3)


def hide_everything(sc: ScenarioConfig, ids: list[str], start_s: float,
                    end_s: float) -> ScenarioConfig:
    """The scenario with an occluder covering each landmark in ``ids`` entirely."""
    covers = tuple(EffectSpec(kind="occlusion", landmark_id=lid, start_s=start_s, end_s=end_s,
                              fraction_start=1.0, fraction_end=1.0) for lid in ids)
    return dataclasses.replace(sc, effects=(*sc.effects, *covers))


def assert_unseen_then_reacquired(flight: Flight, min_unseen_s: float,
                                  reacquire_s: float = REACQUIRE_S) -> None:
    """No fix from a frame where nothing is visible, none reaches the autopilot stamped in
    that time, and a fix within 2 s of a landmark being fully visible again."""
    frames = flight.frames
    unseen = [f for f in frames if max(f.visible.values(), default=0.0) < 0.05]
    assert unseen, "the landmarks never left the view"
    t0, t1 = unseen[0].t_s, unseen[-1].t_s
    assert t1 - t0 >= min_unseen_s, f"unseen only {t1 - t0:.2f} s"
    assert [f.index for f in unseen if f.fix_ned_m is not None] == [], "invented fix"
    assert not flight.invented(), flight.invented()[:3]
    stale = [a for a in flight.fake.arrivals if t0 + 0.05 <= a.stamp_s <= t1 - 0.05]
    assert not stale, f"{len(stale)} fixes stamped while nothing was visible: {stale[:2]}"
    back = next(f.t_s for f in frames if f.t_s > t1 and max(f.visible.values(), default=0) > 0.99)
    fixed = next((f.t_s for f in frames if f.t_s >= back and f.fix_ned_m is not None), None)
    assert fixed is not None and fixed - back <= reacquire_s, (back, fixed)
    fused = next((a.stamp_s for a in flight.fake.arrivals if a.accepted and a.stamp_s >= back),
                 None)
    assert fused is not None and fused - back <= reacquire_s, (back, fused)
    print(f"unseen {t0:.2f}..{t1:.2f} s, fully visible again {back:.2f} s, first fix "
          f"+{fixed - back:.2f} s, first fused +{fused - back:.2f} s")


async def test_occlusion_hides_every_landmark(settings: Settings) -> None:
    """An occluder hides every landmark in view for 3 s: no fix while hidden, none stale
    afterwards, and re-acquired within 2 s of the occluder going away."""
    sc = load_scenario("hover")
    ids = ["wall-01", "wall-02", "sign-01", "sign-02"]
    flight = await Flight(hide_everything(sc, ids, 4.0, 7.0), 11.0, settings).run()
    hidden = [f for f in flight.frames if 4.1 <= f.t_s <= 6.9]
    assert hidden and all(max(f.visible.values(), default=0) < 0.05 for f in hidden), \
        "the occluder did not hide the landmarks"
    assert fix_share(flight.frames, 1.0, 4.0) > 0.5, "no fixes before the occlusion"
    assert_unseen_then_reacquired(flight, 2.5)


@pytest.fixture(scope="module")
def leave_reenter(tmp_path_factory: pytest.TempPathFactory) -> Flight:
    """leave_reenter with shorter holds (3 s before turning away, 3 s looking south), and the
    hover's slow sway (a perfectly still view is not acquired: see docs/reliability.md)."""
    sc = load_scenario("leave_reenter")
    w = sc.trajectory.waypoints
    waypoints = (dataclasses.replace(w[0], hold_s=3.0), dataclasses.replace(w[1], hold_s=3.0),
                 w[2])
    hover = load_scenario("hover")
    sc = dataclasses.replace(sc, trajectory=dataclasses.replace(
        sc.trajectory, waypoints=waypoints, sway_m=hover.trajectory.sway_m,
        sway_period_s=hover.trajectory.sway_period_s))
    settings = sitl_settings(tmp_path_factory.mktemp("leave_reenter"))
    return asyncio.run(Flight(sc, 16.0, settings).run())


def test_no_fix_while_landmarks_out_of_view(leave_reenter: Flight) -> None:
    """Every landmark leaves the view for ~4 s: no fix from those frames, none stamped in
    that time reaches the autopilot, and fixes come back afterwards."""
    assert fix_share(leave_reenter.frames, 1.0, 3.0) > 0.5, "no fixes before turning away"
    assert_unseen_then_reacquired(leave_reenter, 2.0, reacquire_s=math.inf)


def test_reacquired_within_2s_of_reentering_view(leave_reenter: Flight) -> None:
    """After turning back, a landmark is re-acquired within 2 s of being fully in view."""
    assert_unseen_then_reacquired(leave_reenter, 2.0, reacquire_s=REACQUIRE_S)
