"""Where the demo's heavy frames wait: each track update's wall, CPU and run-queue time.

``companion demo`` runs in this process (the same flight as the command, on both cores) with
every track update timed from inside (``TrackSet._update_one``, on the frame worker and on
the second track thread): its wall time, the CPU its thread spent (``time.thread_time``) and
the time that thread waited on a run queue -- runnable, no core given to it (the kernel's
``/proc/thread-self/schedstat``).  An update whose wall time is much longer than its CPU
waited for a core (the run queue) or for the GIL or a lock (the rest).  Prints the demo's
capture -> wire and ``process`` p50 / p99, and for the track updates longer than
``--heavy-ms`` their wall, CPU and run-queue sums::

    PYTHONPATH=. .venv/bin/python benchmarks/demo_threads.py --runs 3
    PYTHONPATH=. .venv/bin/python benchmarks/demo_threads.py --runs 3 --free   # alternated

``--free`` alternates each run with one whose frame threads are left to the scheduler
(``perception.keep_frame_cores = false``; :mod:`companion.cores` keeps them on a core each
while the machine leaves them free): docs/benchmarks.md, "Latency tail (issue 23)",
2026-12-05 afternoon.  Run another checkout's code with ``PYTHONPATH`` set to it.  Linux
only.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def runqueue_s(path: str = "/proc/thread-self/schedstat") -> float:
    """Seconds the thread has waited on a run queue so far (schedstat's second field; 0
    where the kernel keeps no scheduler statistics)."""
    try:
        with open(path) as fh:
            return int(fh.read().split()[1]) / 1e9
    except (OSError, IndexError, ValueError):
        return 0.0


def instrument() -> list[tuple[str, float, float, float]]:
    """Wrap the track update; returns the list it fills: (thread, wall, CPU, run queue) in
    ms per update."""
    from companion import tracks

    updates: list[tuple[str, float, float, float]] = []
    inner = tracks.TrackSet._update_one

    def timed(self: Any, *args: Any, **kw: Any) -> bool:
        name = threading.current_thread().name
        t0, c0, q0 = time.perf_counter(), time.thread_time(), runqueue_s()
        try:
            return bool(inner(self, *args, **kw))
        finally:
            updates.append((name, (time.perf_counter() - t0) * 1e3,
                            (time.thread_time() - c0) * 1e3, (runqueue_s() - q0) * 1e3))

    tracks.TrackSet._update_one = timed  # type: ignore[method-assign]
    return updates


def summary(demo: dict[str, Any], updates: list[tuple[str, float, float, float]],
            heavy_ms: float) -> dict[str, Any]:
    """The demo's latency and the heavy track updates' wall, CPU and run-queue sums."""
    heavy = [u for u in updates if u[1] > heavy_ms]
    ratio = sorted(w / c for _, w, c, _ in updates if c > 1.0)
    return {
        "capture_to_wire_p50_p99": [demo["latency_p50_ms"], demo["latency_p99_ms"]],
        "process_p50_p99": [demo["stage_ms"]["process"]["p50"],
                            demo["stage_ms"]["process"]["p99"]],
        "dropped": demo["dropped_frames"], "cores": demo["cpu_cores_busy"],
        "fixes_sent": demo["fixes_sent"], "rmse_pct": demo["position_rmse_pct_of_distance"],
        "updates": len(updates), "heavy_updates": len(heavy),
        "heavy_wall_s": round(sum(u[1] for u in heavy) / 1e3, 2),
        "heavy_cpu_s": round(sum(u[2] for u in heavy) / 1e3, 2),
        "heavy_runqueue_s": round(sum(u[3] for u in heavy) / 1e3, 2),
        "wall_per_cpu_p50_p90": [round(ratio[len(ratio) // 2], 2),
                                 round(ratio[int(0.9 * len(ratio))], 2)] if ratio else None,
    }


def child(seconds: float, free: bool, heavy_ms: float) -> None:
    """One demo in this process; prints ``RESULT {json}``."""
    from companion.launch import limit_library_threads, main

    limit_library_threads()
    updates = instrument()
    out = io.StringIO()
    extra = ["--set", "perception.keep_frame_cores=false"] if free else []
    with contextlib.redirect_stdout(out):
        status = main(["demo", "--seconds", str(seconds), "--json", *extra])
    if status != 0:
        raise SystemExit(f"companion demo exited {status}")
    print("RESULT " + json.dumps(summary(json.loads(out.getvalue()), updates, heavy_ms)))


def run_child(seconds: float, free: bool, heavy_ms: float) -> dict[str, Any]:
    import subprocess

    cmd = [sys.executable, __file__, "--child", "--seconds", str(seconds),
           "--heavy-ms", str(heavy_ms)] + (["--free"] if free else [])
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    for text in done.stdout.splitlines():
        if text.startswith("RESULT "):
            result: dict[str, Any] = json.loads(text[7:])
            return result
    raise SystemExit(f"demo run failed:\n{done.stderr[-3000:]}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--free", action="store_true",
                    help="alternate with runs whose frame threads are left to the scheduler")
    ap.add_argument("--heavy-ms", type=float, default=6.0,
                    help="track updates longer than this are summed (default 6 ms)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not hasattr(os, "sched_getaffinity"):
        raise SystemExit("demo_threads.py reads Linux's scheduler statistics: Linux only")
    if args.child:
        child(args.seconds, args.free, args.heavy_ms)
        return 0
    variants = (True, False) if args.free else (False,)
    by: dict[bool, list[dict[str, Any]]] = {v: [] for v in variants}
    for i in range(args.runs):
        for free in variants:
            r = run_child(args.seconds, free, args.heavy_ms)
            by[free].append(r)
            label = "free" if free else "as shipped"
            print(f"run {i + 1} {label:<10} " + json.dumps(r), flush=True)
    for free, runs in by.items():
        p99 = [r["capture_to_wire_p50_p99"][1] for r in runs]
        queue = [r["heavy_runqueue_s"] / max(r["heavy_wall_s"], 1e-9) for r in runs]
        print(f"{'free' if free else 'as shipped'}: capture -> wire p99 median "
              f"{statistics.median(p99):.1f} ms ({', '.join(f'{v:.1f}' for v in p99)}); "
              f"heavy updates' wall on a run queue {statistics.median(queue):.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
