"""Heartbeat period jitter while the CPU is saturated (target: jitter <= 50 ms).

The companion's bridge runs here (pymavlink backend, 1 Hz heartbeat) next to a "tracker"
thread doing numpy + pure-Python work; one CPU-burning subprocess per core keeps every core
busy; the fake autopilot runs as its own process (``companion fake-autopilot``) and measures
the arrival period of our heartbeats.  Jitter = |period - median period|.

    PYTHONPATH=. .venv/bin/python benchmarks/mavlink_heartbeat_jitter.py [--seconds 30]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig

ROOT = Path(__file__).resolve().parents[1]
BURN = "import time\nx = 0\nwhile True:\n    x = (x * 31 + 7) % 1000003\n"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def tracker_load(stop: threading.Event) -> None:
    """Stand-in for the tracker's executor thread: numpy (GIL released) + Python (GIL held)."""
    rng = np.random.default_rng(0)
    a = rng.random((300, 300))
    while not stop.is_set():
        a = np.tanh(a @ a.T / 300.0)
        sum(i * i for i in range(20_000))


async def run_bridge(port: int, seconds: float) -> dict[str, int]:
    cfg = MavlinkConfig(endpoint=f"udpout:127.0.0.1:{port}", set_origin=False, link_timeout_s=5.0)
    async with PymavlinkBridge(cfg) as bridge:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            bridge.report_health("ok")  # the pipeline reports progress
            await asyncio.sleep(0.1)
        return dict(bridge.link.counters)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--no-load", action="store_true", help="baseline without CPU load")
    args = parser.parse_args()
    port = free_udp_port()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    burners = (
        []
        if args.no_load
        else [subprocess.Popen([sys.executable, "-c", BURN]) for _ in range(os.cpu_count() or 2)]
    )
    stop = threading.Event()
    tracker = threading.Thread(target=tracker_load, args=(stop,), daemon=True)
    with tempfile.TemporaryDirectory() as tmp:
        summary = Path(tmp) / "fake.json"
        fake = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "companion",
                "fake-autopilot",
                "--endpoint",
                f"udpin:127.0.0.1:{port}",
                "--seconds",
                str(args.seconds + 4),
                "--summary",
                str(summary),
            ],
            cwd=ROOT,
            env=env,
            stderr=subprocess.DEVNULL,
        )
        try:
            time.sleep(2.0)  # let the fake start
            if not args.no_load:
                tracker.start()
            counters = asyncio.run(run_bridge(port, args.seconds))
        finally:
            stop.set()
            for b in burners:
                b.kill()
            fake.wait(timeout=30)
        stats = json.loads(summary.read_text())["heartbeat_period_s"]
    load = "no load" if args.no_load else f"{len(burners)} burners + tracker thread"
    print(f"heartbeat over {args.seconds:.0f} s with {load}: sent {counters['heartbeats_sent']}")
    print(
        "period median {median:.4f} s, min {min:.4f} s, max {max:.4f} s, "
        "jitter p99 {jitter_p99:.4f} s, jitter max {jitter_max:.4f} s".format(**stats)
    )


if __name__ == "__main__":
    main()
