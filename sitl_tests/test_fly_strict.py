"""``companion run --fly`` (the docs/sitl.md closed loop) against the strict fake autopilot.

The fake plays SITL: it flies the vehicle itself from the companion's GUIDED commands
(``vehicle="guided"``), sends the simulator's truth (SIM_STATE) only when asked, fuses the
fixes in its own estimator gated against its own estimate, and runs Copter's EKF failsafe.
The vehicle starts hovering at the square's first corner (``guided_airborne_m``): from the
ground the sample street gives no fix (docs/sitl.md).

* An 8 s vision outage in flight: flags drop, "EKF Failsafe: changed to LAND Mode", the
  heartbeat says LAND; the companion says why in one line and ``run --fly`` exits 3.
* Three laps of the square: no EKF failsafe, the longest gap between fused fixes while
  airborne under 1 s, the fake's estimate within 0.10 m (median) / 0.5 m (max) of truth.
  The fake's height comes from its barometer, as the profile's ``EK3_SRC1_POSZ`` 1 asks
  (mavlink_bridge/fake_baro.py); the printed line splits the error into horizontal and down.
  A late fix is compared at ArduPilot's fusion time horizon (``VISO_DELAY_MS`` left at its
  default 10, as on an autopilot nobody set up: mavlink_bridge/fake_ekf.py).
  Real time (~110 s a seed): marked ``slow``; the issue's five seeds (``SQUARE_SEEDS``),
  where the outage runs one (``SEEDS``); ``SITL_SEEDS=2`` runs the seeds given, for both.
"""

from __future__ import annotations

import asyncio
import os
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.square import SquarePlan, square_corners
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.fake_vehicle import ARDUCOPTER_LAND, PX4_LAND
from tests.run_helpers import fake_and_loop

ROOT = Path(__file__).resolve().parents[1]
HOVER_M = 4.0  # the square's altitude (companion.square.SquarePlan)


def guided(seed: int = 0, **kw: object) -> FakeAutopilotConfig:
    return FakeAutopilotConfig(vehicle="guided", guided_start=(0.0, 0.0, 0.0, 90.0),
                               guided_airborne_m=HOVER_M, seed=seed, **kw)  # type: ignore[arg-type]


def fake_thread(config: FakeAutopilotConfig
                ) -> AbstractContextManager[tuple[FakeAutopilot, asyncio.AbstractEventLoop]]:
    """The fake on its own event loop and thread (``companion run`` owns the main one)."""
    return fake_and_loop(config)


def fly(port: int, tmp_path: Path, seconds: float, *extra: str,
        profile: str = "ardupilot") -> int:
    return main(["run", "--config", str(ROOT / "config" / f"sitl-{profile}.toml"), "--fly",
                 "--seconds", str(seconds), "--set", f"mavlink.endpoint=udpout:127.0.0.1:{port}",
                 "--set", "monitor.enabled=false", "--set", f'flightlog.dir="{tmp_path}"',
                 *extra])


def when(pred: Callable[[], bool], action: Callable[[], None], timeout_s: float) -> None:
    """On a watcher thread: call ``action`` once ``pred`` holds (or give up)."""
    def watch() -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if pred():
                action()
                return
            time.sleep(0.05)
    threading.Thread(target=watch, daemon=True).start()


#: ``SITL_SEEDS=0,1,2``: the fake's and the simulated camera's seeds (the outage: 0 unless
#: given; the square: the issue's five unless given)
SEEDS = [int(v) for v in os.environ.get("SITL_SEEDS", "0").split(",")]
SQUARE_SEEDS = [int(v) for v in os.environ.get("SITL_SEEDS", "0,1,2,3,4").split(",")]


#: per profile: the fake's mode after the failsafe, when it comes after the outage began (the
#: position dropped, then confirmed for 1 s: ArduPilot's 6 s, PX4's EKF2_NOAID_TOUT 5 s), the
#: autopilot's words, and the mode ``--fly`` names
OUTAGE = {
    "ardupilot": (ARDUCOPTER_LAND, (6.0, 8.0),
                  {"VisOdom: not healthy", "EKF Failsafe: changed to LAND Mode"},
                  "LAND", "EKF Failsafe"),
    "px4": (PX4_LAND, (5.0, 7.0), {"Failsafe activated: switching to Land"}, "AUTO.LAND",
            "Failsafe activated"),
}


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
@pytest.mark.parametrize("seed", SEEDS)
def test_an_8s_outage_in_flight_lands_and_stops_fly(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], seed: int, profile: str) -> None:
    land_mode, (soonest, latest), words, mode_name, said = OUTAGE[profile]
    blind: list[float] = []
    with fake_thread(guided(seed, profile=profile)) as (fake, loop):
        def go_blind() -> None:
            blind.append(fake.flight_s())
            loop.call_soon_threadsafe(fake.blind, 8.0)
        when(lambda: len(fake.accepted()) >= 20, go_blind, 30.0)
        status = fly(fake.local_port, tmp_path, 60.0, "--set", f"source.seed={seed}",
                     profile=profile)
        events, texts = list(fake.flight.events), list(fake.statustexts_sent)
        mode, vision = fake.flight.custom_mode, list(fake.vision)
    err = capsys.readouterr().err
    assert blind, "the outage was never started (no fixes fused)"
    land = [t for t, what in events if what == "failsafe LAND"]
    assert land, f"no EKF failsafe: {events}"
    assert soonest <= land[0] - blind[0] <= latest, (blind, land)
    assert mode == land_mode
    assert words <= set(texts), texts
    fused_before = [r for r in vision if r.accepted and r.arrival_s < blind[0]]
    assert len(fused_before) >= 20
    assert status == 3, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"--fly stopped commanding: the autopilot changed mode to {mode_name} "
                           ), err
    assert said in last and "Traceback" not in err
    print(f"{profile} seed {seed}: blind at {blind[0]:.1f} s, LAND {land[0] - blind[0]:.1f} s "
          f"later; {last}")


def visits(path_ne: np.ndarray, corner: tuple[float, float, float], near_m: float = 0.3,
           away_m: float = 1.0) -> int:
    """How many times the path came within ``near_m`` of ``corner`` (horizontally), each
    visit counted once it had gone ``away_m`` from it."""
    dist = np.linalg.norm(path_ne - np.asarray(corner[:2]), axis=1)
    count, away = 0, True
    for d in dist:
        if away and d < near_m:
            count, away = count + 1, False
        elif d > away_m:
            away = True
    return count


def test_visits_counts_each_pass_once() -> None:
    there, between = [6.0, 6.0], [3.0, 3.0]
    path = np.array([between, there, [6.1, 6.0], between, there, there, between])
    assert visits(path, (6.0, 6.0, -4.0)) == 2
    assert visits(path[:3], (6.0, 6.0, -4.0)) == 1
    assert visits(path, (0.0, 0.0, -4.0)) == 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", SQUARE_SEEDS)
def test_three_laps_against_the_strict_fake(tmp_path: Path, seed: int) -> None:
    with fake_thread(guided(seed)) as (fake, _loop):
        status = fly(fake.local_port, tmp_path, 110.0, "--set", f"source.seed={seed}")
        end_s = fake.flight_s()
        events, vision = list(fake.flight.events), list(fake.vision)
        truth_ne = np.array([t[:2] for _, _, t in fake.track])
        diffs = np.array([np.subtract(e, t) for _, e, t in fake.track])
        errors = np.linalg.norm(diffs, axis=1)
        failsafe = fake.flight.failsafe
    fused = [r.arrival_s for r in vision if r.accepted]
    assert fused, "no fix fused"
    gaps = np.diff([*fused, end_s])  # to the companion's end: an outage at the end counts
    median, worst = float(np.median(errors)), float(np.max(errors))
    print(f"seed {seed}: {len(fused)}/{len(vision)} fused, longest gap {gaps.max():.2f} s "
          f"from {fused[int(np.argmax(gaps))]:.1f} s, "
          f"estimate error median {median:.3f} m max {worst:.3f} m (horizontal "
          f"{np.median(np.linalg.norm(diffs[:, :2], axis=1)):.3f} / "
          f"{np.max(np.linalg.norm(diffs[:, :2], axis=1)):.3f}, down "
          f"{np.median(np.abs(diffs[:, 2])):.3f} / {np.max(np.abs(diffs[:, 2])):.3f}), "
          f"events {events[-3:]}")
    assert failsafe is None, events
    assert status == 0
    laps = [visits(truth_ne, c) for c in square_corners(SquarePlan())]
    assert min(laps) >= 3, f"the vehicle reached the corners {laps} times: not three laps"
    assert gaps.max() < 1.0
    assert median < 0.10 and worst < 0.5
