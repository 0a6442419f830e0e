"""Parse cost per incoming datagram (how big a flood the link absorbs), and per bad datagram.

    PYTHONPATH=. .venv/bin/python benchmarks/mavlink_parse.py [--n 20000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from mavlink_bridge.codec import Codec


def frames(n: int) -> list[bytes]:
    out: list[bytes] = []
    c = Codec(1, 1)
    c.set_writer(out.append)
    for i in range(n):
        c.mav.attitude_send(i, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
    return out


def per_item_us(codec: Codec, items: list[bytes], repeats: int = 5) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        for d in items:
            codec.feed(d, True)
        runs.append((time.perf_counter_ns() - t0) / 1000 / len(items))
    return statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20_000)
    args = parser.parse_args()
    good = frames(args.n)
    rng = np.random.default_rng(0)
    garbage = [rng.integers(0, 256, 60, dtype=np.uint8).tobytes() for _ in range(args.n)]
    bad_crc = [g[:-1] + bytes([g[-1] ^ 0xFF]) for g in good]
    for name, items in (("valid ATTITUDE", good), ("random bytes", garbage), ("bad CRC", bad_crc)):
        us = per_item_us(Codec(1, 197), items)
        print(f"{name:15s} {us:6.1f} us per datagram -> {1e6 / us:8.0f} datagrams/s on one core")


if __name__ == "__main__":
    main()
