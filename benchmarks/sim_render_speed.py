"""How fast the simulated camera renders (640x480 unless the scenario says otherwise).

Run: ``PYTHONPATH=. python benchmarks/sim_render_speed.py [--frames N] [--scenarios a,b]``.
OpenCV is limited to one thread (``cv2.setNumThreads(1)``) so the number is per core.
Prints, per scenario, the median / 90th-percentile milliseconds per frame and the frame
rate the median allows, then a realtime check: the simulated camera run live at the
scenario's rate for a few seconds, counting frames it had to drop because it was late.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import time

import cv2
import numpy as np

from companion.sim.scenario import SCENARIO_DIR, load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource


def time_render(sim: Simulator, frames: int) -> np.ndarray:
    total = max(1, round(sim.scenario.seconds * sim.fps))
    indices = np.linspace(0, total - 1, frames).round().astype(int)
    sim.render(0)  # warm-up: textures, caches
    out = []
    for i in indices:
        t0 = time.perf_counter()
        sim.render(int(i))
        out.append((time.perf_counter() - t0) * 1000.0)
    return np.asarray(out)


async def live(sim: Simulator, seconds: float) -> tuple[int, int]:
    source = SimCameraSource(sim, realtime=True, seconds=seconds)
    delivered = 0
    try:
        while True:
            await source.recv()
            delivered += 1
    except EOFError:
        pass
    return delivered, source.status.skip_reasons.get("late", 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--live-seconds", type=float, default=4.0)
    parser.add_argument("--scenarios", default=",".join(
        sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))))
    args = parser.parse_args()
    cv2.setNumThreads(1)
    print(f"cpu count {os.cpu_count()}, OpenCV threads {cv2.getNumThreads()}")
    print(f"{'scenario':<18} {'size':>8} {'median ms':>10} {'p90 ms':>8} {'fps@median':>11}")
    for name in args.scenarios.split(","):
        sim = Simulator(load_scenario(name))
        ms = time_render(sim, args.frames)
        cam = sim.scenario.camera
        med, p90 = float(np.median(ms)), float(np.percentile(ms, 90))
        print(f"{name:<18} {cam.width}x{cam.height:<4} {med:>10.2f} {p90:>8.2f} "
              f"{1000.0 / med:>11.1f}")
    sim = Simulator(load_scenario("survey"))
    delivered, late = asyncio.run(live(sim, args.live_seconds))
    print(f"live survey at {sim.fps:g} fps for {args.live_seconds:g} s: {delivered} frames "
          f"delivered, {late} dropped as late")


if __name__ == "__main__":
    main()
