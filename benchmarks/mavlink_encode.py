"""Encode + send cost per vision message (target <= 30 us), pymavlink backend.

Runs a real bridge over UDP loopback against a fake autopilot, then times ``send_fix_now``
(gate checks + field building + pymavlink encode + CRC + signing if set + socket write)
for each output kind.  The gate's rate limit is lifted for the measurement only.

    PYTHONPATH=. .venv/bin/python benchmarks/mavlink_encode.py [--n 5000] [--signed]
"""

from __future__ import annotations

import argparse
import asyncio
import hashlib
import statistics
import tempfile
import time

from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.messages import VisionFix
from mavlink_bridge.output import OutputGate

COV = tuple(0.01 if k in (0, 6, 11) else 0.0 for k in range(21))


async def measure(output: str, profile: str, n: int, key_file: str) -> list[float]:
    fake_cfg = FakeAutopilotConfig(
        profile=profile,  # type: ignore[arg-type]
        signing_key=hashlib.sha256(b"bench").digest() if key_file else None,
    )
    async with FakeAutopilot(fake_cfg) as ap:
        cfg = MavlinkConfig(
            endpoint=f"udpout:127.0.0.1:{ap.local_port}",
            profile=profile,  # type: ignore[arg-type]
            output=output,
            set_origin=False,
            signing_key_file=key_file,
        )  # type: ignore[arg-type]
        async with PymavlinkBridge(cfg) as bridge:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 5.0)
            # lift the rate limit: we time the cost per message, not the rate
            bridge.vision_gate = OutputGate(rate_hz=1e9, max_age_us=10**12)
            t0 = time.monotonic_ns() // 1000
            times = []
            for i in range(n):
                fix = VisionFix(
                    t0 + 20_000 * (i + 1),
                    (1.0, 2.0, -3.0),
                    (0.01, 0.02, 1.0),
                    COV,
                    quality_percent=90,
                    reset_counter=0,
                )
                start = time.perf_counter_ns()
                result = bridge.send_fix_now(fix)
                times.append((time.perf_counter_ns() - start) / 1000)
                assert result == "sent", result
                if i % 200 == 199:
                    await asyncio.sleep(0.005)  # let the fake drain its socket
            return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5000)
    parser.add_argument("--signed", action="store_true", help="also measure with signing")
    args = parser.parse_args()
    with tempfile.NamedTemporaryFile("w", suffix=".key") as kf:
        kf.write("bench\n")
        kf.flush()
        cases = [("odometry", "ardupilot", ""), ("vpe", "ardupilot", ""), ("odometry", "px4", "")]
        if args.signed:
            cases.append(("odometry", "ardupilot", kf.name))
        for output, profile, key in cases:
            t = asyncio.run(measure(output, profile, args.n, key))
            t.sort()
            print(
                f"{output:8s} {profile:9s} {'signed' if key else 'unsigned':8s} "
                f"n={len(t)} median {statistics.median(t):6.1f} us  "
                f"p90 {t[int(0.9 * len(t))]:6.1f} us  p99 {t[int(0.99 * len(t))]:6.1f} us"
            )


if __name__ == "__main__":
    main()
