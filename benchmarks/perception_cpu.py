"""CPU time per frame of the perception, by stage, on rendered frames (no clock, no load).

The deterministic replay of ``tests/test_perception.py``'s ``flight()`` (true attitude, the
committed detector, ``process`` then ``housekeeping`` for every frame, one after the other):
prints the fixes and their RMSE against the truth -- the same on two checkouts when a
change alters no result -- and the CPU time of each stage per frame (``time.thread_time``
of the thread that ran it, so the second track thread's share is counted where it ran;
``process`` and ``housekeeping`` with ``time.process_time``, every thread).  CPU time does
not depend on what else runs on the machine, so two checkouts compare under any load::

    PYTHONPATH=. .venv/bin/python benchmarks/perception_cpu.py --scenario survey --frames 0:900
    PYTHONPATH=. .venv/bin/python benchmarks/perception_cpu.py --max-tracks 2 --particles 100

``--max-tracks`` / ``--particles`` / ``--scale`` / ``--track-every`` are the settings a
slower board lowers (docs/deploy.md); ``--profile N`` adds cProfile's N costliest
functions (main thread's CPU time).
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import json
import math
import pstats
import sys
import time
from collections.abc import Callable
from typing import Any

from companion.launch import limit_library_threads

# one thread per native pool, as `companion` runs, before numpy loads: OpenBLAS's idle
# threads spin, and their CPU time counted in every stage (3.9 ms a frame without this)
limit_library_threads()

import numpy as np  # noqa: E402

#: the perception's, then the parts' (class.method: companion/corners.py, tracks.py)
STAGES = ("process", "housekeeping", "tracker.update", "Corners.align", "Corners.recover",
          "Corners.check", "TrackSet.verify", "Perception._solve")


class Meter:
    """CPU time (ms) per call of wrapped methods, and per frame."""

    def __init__(self) -> None:
        self.calls: dict[str, list[float]] = {k: [] for k in STAGES}
        self.frame: dict[str, float] = {}
        self.frames: dict[str, list[float]] = {k: [] for k in STAGES}

    def wrap(self, cls: Any, attr: str, name: str, clock: Callable[[], float]) -> None:
        inner = getattr(cls, attr)

        def timed(obj: Any, *args: Any, **kw: Any) -> Any:
            c0 = clock()
            try:
                return inner(obj, *args, **kw)
            finally:
                ms = (clock() - c0) * 1e3
                self.calls[name].append(ms)
                self.frame[name] = self.frame.get(name, 0.0) + ms

        setattr(cls, attr, timed)

    def end_frame(self) -> None:
        for k in STAGES:
            self.frames[k].append(self.frame.get(k, 0.0))
        self.frame = {}


def pct(values: list[float], q: float) -> float:
    return round(float(np.percentile(values, q)), 2) if values else 0.0


def configs(args: argparse.Namespace) -> dict[str, Any]:
    """Perception's keyword arguments for ``--layer``, ``--max-tracks``, ``--particles``."""
    from companion.perception import PerceptionConfig
    from tracker import TrackerConfig
    from tracker.config import replace as replace_tracker

    if args.layer == "flight":
        from tracker.detector import Detector

        kw: dict[str, Any] = {"config": PerceptionConfig(), "tracker_config": TrackerConfig(),
                              "detect": Detector().detect}
    else:
        from companion.runtime import detector_for
        from companion.settings import load_settings

        st = load_settings(shipped=("sim",))
        kw = {"config": st.perception, "tracker_config": st.tracker, "pose_config": st.pose,
              "acquire_config": st.acquire, "gate_config": st.fixgate,
              "detect": detector_for(st)}
    if args.serial:
        kw["config"] = dataclasses.replace(kw["config"], parallel_tracks=False)
    if args.max_tracks is not None:
        kw["config"] = dataclasses.replace(kw["config"], max_tracks=args.max_tracks)
    if args.track_every is not None:
        kw["config"] = dataclasses.replace(kw["config"], track_every_frames=args.track_every)
    if args.particles is not None:
        kw["tracker_config"] = replace_tracker(kw["tracker_config"], particles=args.particles)
    return kw


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="survey")
    ap.add_argument("--frames", default="0:900", help="first:end")
    ap.add_argument("--max-tracks", type=int, help="perception.max_tracks (default: its own)")
    ap.add_argument("--particles", type=int, help="tracker particles (default: its own)")
    ap.add_argument("--track-every", type=int,
                    help="perception.track_every_frames (default: its own)")
    ap.add_argument("--scale", type=float, default=1.0,
                    help="camera resolution scale (0.5: 320x240 for 640x480)")
    ap.add_argument("--layer", choices=("flight", "sim"), default="sim",
                    help="sim: the settings `companion demo` runs with (config/sim.toml, its "
                    "detector); flight: tests/test_perception.py's flight() defaults")
    ap.add_argument("--serial", action="store_true",
                    help="perception.parallel_tracks = false (every track on one thread)")
    ap.add_argument("--profile", type=int, default=0, metavar="N")
    ap.add_argument("--json", action="store_true", help="one JSON line instead of text")
    args = ap.parse_args()

    import cv2

    from companion.corners import Corners
    from companion.demo import map_landmarks
    from companion.perception import Perception, SideSensors
    from companion.sim.scenario import load_scenario
    from companion.sim.simulator import Simulator
    from companion.sources.base import Frame
    from companion.tracks import TrackSet
    from tracker.pose.types import AttitudeSample, PoseFix

    cv2.setNumThreads(1)  # as the companion runs it (companion.runtime.CompanionFlight)
    scenario = dataclasses.replace(load_scenario(args.scenario), seconds=60)
    if args.scale != 1.0:
        cam = scenario.camera
        scenario = dataclasses.replace(scenario, camera=dataclasses.replace(
            cam, width=round(cam.width * args.scale), height=round(cam.height * args.scale),
            fx=cam.fx * args.scale, fy=cam.fy * args.scale,
            cx=cam.cx * args.scale, cy=cam.cy * args.scale))
    sim = Simulator(scenario)
    landmarks, references = map_landmarks(sim)

    def sensors(t_us: int) -> SideSensors:
        s = sim.state_at(t_us / 1e6)
        return SideSensors(attitude=AttitudeSample(t_us, *map(float, s.attitude_rpy_rad)))

    perception = Perception(sim.scenario.camera, landmarks, references, sensors=sensors,
                            **configs(args))
    meter = Meter()
    meter.wrap(Perception, "process", "process", time.process_time)
    meter.wrap(Perception, "housekeeping", "housekeeping", time.process_time)
    parts = {"Corners": Corners, "TrackSet": TrackSet, "Perception": Perception}
    for name in STAGES[3:]:
        owner, attr = name.split(".")
        meter.wrap(parts[owner], attr, name, time.thread_time)
    first_update = True
    # CPU time of the main thread (wall time would count the machine's load)
    profiler = cProfile.Profile(time.thread_time) if args.profile else None
    errors, tracks_per_frame = [], []
    start, end = (int(v) for v in args.frames.split(":"))
    for i in range(start, end):
        image, _ = sim.render(i)
        frame = Frame(i, round(i * 1e6 / sim.fps), image)
        if profiler is not None:
            profiler.enable()
        result = perception.process(frame)
        perception.housekeeping(frame)
        if profiler is not None:
            profiler.disable()
        if first_update and perception.tracks:  # the tracker's class, once one exists
            cls = type(next(iter(perception.tracks.values())).tracker)
            meter.wrap(cls, "update", "tracker.update", time.thread_time)
            first_update = False
        meter.end_frame()
        tracks_per_frame.append(len(perception.tracks))
        if isinstance(result.fix, PoseFix):
            errors.append(math.dist(result.fix.position_ned_m,
                                    sim.state_at(i / sim.fps).position_ned_m))
    perception.close()
    rmse = float(np.sqrt(np.mean(np.square(errors)))) if errors else None
    out = {"scenario": args.scenario, "layer": args.layer, "frames": args.frames,
           "scale": args.scale, "max_tracks": args.max_tracks, "particles": args.particles,
           "fixes": len(errors),
           "rmse_m": None if rmse is None else round(rmse, 4),
           "tracks_mean": round(float(np.mean(tracks_per_frame)), 2),
           "cpu_ms_per_frame": {k: {"mean": round(float(np.mean(v)), 2), "p50": pct(v, 50),
                                    "p99": pct(v, 99), "max": pct(v, 100)}
                                for k, v in meter.frames.items()},
           "calls": {k: len(v) for k, v in meter.calls.items()}}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{args.scenario} ({args.layer} settings) frames {args.frames}: "
              f"{out['fixes']} fixes, RMSE "
              f"{out['rmse_m']} m, {out['tracks_mean']} tracks on average")
        print("CPU ms per frame (mean / p50 / p99 / max):")
        for k, v in out["cpu_ms_per_frame"].items():
            print(f"  {k:<18} {v['mean']:7.2f} {v['p50']:7.2f} {v['p99']:7.2f} {v['max']:7.2f}"
                  f"   ({out['calls'][k]} calls)")
    if profiler is not None:
        pstats.Stats(profiler, stream=sys.stdout).sort_stats("tottime").print_stats(
            args.profile)
    return 0


if __name__ == "__main__":
    sys.exit(main())
