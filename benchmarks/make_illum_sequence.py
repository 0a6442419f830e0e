"""Write the simulated illumination-change sequence in OTB layout.

    PYTHONPATH=. python benchmarks/make_illum_sequence.py OUT_DIR [--frames 200] [--seed 0]

640x480, a 56x40 sign on a cluttered colour background moving on a Lissajous path (up to
~5 px/frame), global gain cycling 1.25 -> 0.55 -> 1.25 with a +-12 % colour cast, sensor noise
sigma 3; JPEG quality 95.  Deterministic for a given seed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from companion.evaluation.synthetic import SynthSpec, write_otb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    seq = write_otb(SynthSpec(frames=args.frames, seed=args.seed), args.out)
    print(f"wrote {len(seq.frames)} frames to {args.out}")


if __name__ == "__main__":
    main()
