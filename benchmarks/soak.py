"""Soak: a long simulated flight of the real ``companion run`` process, watched for leaks.

The companion runs as its own process (``python -m companion run``) on a hover scenario
stretched to the soak's length, against the fake autopilot in this process on UDP loopback,
with monitoring (Zenoh) and the flight log on, as deployed.  Every ``--sample-s`` this script
records the companion's resident memory, open file descriptors and threads (psutil) and the
fixes the autopilot fused in that interval.  After a warm-up (default: 10 % of the flight,
at least 15 s) it checks:

* resident memory grows by at most 5 %: the floor of each interval (read every 0.25 s: what
  the process keeps between transient buffers), last vs the first after warm-up; and the
  interval's peak (Linux's VmHWM), the highest after warm-up vs the first third's highest;
* open file descriptors and threads do not grow (the peak of the last third of the samples
  is at most the peak of the first third: thread pools start their threads lazily);
* the fix rate is steady: no interval after warm-up without fused fixes, and the median rate
  of the second half is >= 70 % of the first half's (a slowing pipeline shows as a trend;
  single intervals vary with the load of the shared machine).

The flight runs in real time (the MAVLink stack and the fake autopilot run on the monotonic
clock), so 30 minutes take 30 minutes:

    PYTHONPATH=. python benchmarks/soak.py --minutes 30 --json soak-30min.json --plot soak.png

``LMC_SOAK_MINUTES`` sets the default length; CI runs ``sitl_tests/test_soak.py``, a 75 s
form of the same checks (a 30 s warm-up).  Exit status 0 when every check passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402

from testsupport.soak import plot, soak  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float,
                        default=float(os.environ.get("LMC_SOAK_MINUTES", "30")))
    parser.add_argument("--sample-s", type=float, default=10.0)
    parser.add_argument("--fps", type=float, default=15.0)
    parser.add_argument("--json", type=Path, help="write samples and verdict here")
    parser.add_argument("--plot", type=Path, help="draw the memory over the flight (PNG)")
    args = parser.parse_args()
    result = asyncio.run(soak(args.minutes * 60, args.sample_s, args.fps))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1), encoding="utf-8")
    if args.plot:
        cv2.imwrite(str(args.plot), plot(result))
    for s in result["samples"]:
        print(f"{s['t_s']:8.1f} s  rss {s['rss_mb']:8.2f} MB (peak {s['rss_peak_mb']:8.2f})  "
              f"fds {s['fds']:3d}  "
              f"threads {s['threads']:3d}  fused {s['fused']:4d}")
    print(json.dumps(result["verdict"], indent=1))
    return 0 if result["verdict"]["ok"] and result["exit_status"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
