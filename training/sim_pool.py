"""Build the detector's training pool from the simulated world (runs in the project's venv).

    PYTHONPATH=. .venv/bin/python -m training.sim_pool --count 8000 --out /tmp/det/sim_pool.npz

Each scene (:func:`training.sim_data.sim_scene`, seeds ``--seed`` + i) is rendered at
``size / SCALE`` pixels square and shrunk to ``size`` exactly as the detector's letterbox
shrinks a 640x480 frame to 416 (``INTER_AREA``, scale 0.65), so a landmark has the same
size and look in training as in use. A face is a target when at least 30 % of it is in the
image and at most half of it hidden (its box is the visible part, as usual for YOLO
crops). Saved: ``images`` (N, size, size, 3) uint8 BGR and ``targets`` rows
(image, class, cx, cy, w, h) in pool pixels. Progress is printed every 500 scenes.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from training.args import positive
from training.sim_data import sim_scene

SCALE = 416 / 640  # the letterbox's scale for a 640x480 frame
MIN_IN_VIEW, MAX_HIDDEN = 0.3, 0.5  # which faces are training targets


def pool_item(seed: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """One pool image and its target rows (class, cx, cy, w, h) in pool pixels."""
    side = round(size / SCALE)
    scene = sim_scene(np.random.default_rng(seed), side, side)
    small = cv2.resize(scene.image_bgr, (size, size), interpolation=cv2.INTER_AREA)
    keep, _ = scene.split(MIN_IN_VIEW, MAX_HIDDEN)
    b = scene.boxes_xywh[keep] * (size / side)
    rows = np.column_stack([scene.classes[keep], b[:, 0] + b[:, 2] / 2, b[:, 1] + b[:, 3] / 2,
                            b[:, 2], b[:, 3]]).astype(np.float32)
    return small, rows.reshape(-1, 5)


def _chunk(args: tuple[int, int, int]) -> tuple[np.ndarray, list[np.ndarray]]:
    start, count, size = args
    items = [pool_item(start + i, size) for i in range(count)]
    return np.stack([im for im, _ in items]), [r for _, r in items]


def build(out: Path, count: int, size: int, seed: int, workers: int) -> None:
    """Render ``count`` scenes with ``workers`` processes and save the pool to ``out``."""
    images = np.empty((count, size, size, 3), np.uint8)
    targets: list[np.ndarray] = []
    step, t0 = 500, time.monotonic()
    jobs = [(seed + i, min(step, count - i), size) for i in range(0, count, step)]
    with ProcessPoolExecutor(workers) as pool:
        for k, (ims, rows) in enumerate(pool.map(_chunk, jobs)):
            i0 = k * step
            images[i0:i0 + len(ims)] = ims
            for j, r in enumerate(rows):
                targets.append(np.column_stack([np.full(len(r), i0 + j, np.float32), r]))
            print(f"{i0 + len(ims)}/{count} scenes, {time.monotonic() - t0:.0f} s", flush=True)
    all_rows = np.concatenate(targets).astype(np.float32).reshape(-1, 6)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out, images=images, targets=all_rows)
    print(f"saved {out}: {count} images, {len(all_rows)} boxes", flush=True)


def main() -> None:
    """Command line."""
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=positive, default=8000)
    ap.add_argument("--size", type=positive, default=256)
    ap.add_argument("--seed", type=int, default=1, help="scene i uses seed + i")
    ap.add_argument("--workers", type=positive, default=2)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    build(args.out, args.count, args.size, args.seed, args.workers)


if __name__ == "__main__":
    main()
