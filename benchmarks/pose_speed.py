"""Speed of one pose fix for 1, 2, 4 and 8 landmarks in view (median microseconds).

Run: PYTHONPATH=. python benchmarks/pose_speed.py [--repeats N]

Every landmark is seen with its four corners and 1 px noise; "no attitude" uses IPPE (one
landmark) or PnP-RANSAC, "attitude" uses IPPE or bearing least squares with the autopilot
attitude as a prior.  The figure includes validation, association of labelled observations,
solving, refinement and covariance.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from tracker.camera import CameraModel
from tracker.pose import AttitudeSample, MapLandmark, PoseFix, solve_pose
from tracker.pose.simulate import SensorNoise, observe_landmark

CAMERA = CameraModel()
P = np.array([0.0, 0.0, -5.0])
RPY = (0.02, -0.02, 0.03)


def landmarks(n: int) -> tuple[MapLandmark, ...]:
    """``n`` signs spread over the view at 8-20 m, facing the camera."""
    rng = np.random.default_rng(n)
    out = []
    for i in range(n):
        north = 6.0 + 14.0 * i / max(n - 1, 1)
        east = north * (0.5 * ((i * 0.618) % 1.0) - 0.25)
        down = -5.0 + north * (0.3 * ((i * 0.382) % 1.0) - 0.15)
        facing = 180.0 + float(rng.uniform(-20, 20))
        out.append(MapLandmark(f"L{i}", (north, east, down), 1.5, 1.5, facing, "sign"))
    return tuple(out)


def time_fixes(n: int, use_attitude: bool, repeats: int) -> tuple[float, str]:
    """Median microseconds per fix and the solver used."""
    lms = landmarks(n)
    rng = np.random.default_rng(0)
    obs = [observe_landmark(lm, CAMERA, P, RPY, rng, SensorNoise()) for lm in lms]
    seen = [o for o in obs if o is not None]
    assert len(seen) == n, f"only {len(seen)} of {n} landmarks in view"
    att = AttitudeSample(0, *RPY) if use_attitude else None
    fix = solve_pose(seen, lms, CAMERA, 0, attitude=att)
    assert isinstance(fix, PoseFix), fix
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        solve_pose(seen, lms, CAMERA, 0, attitude=att)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e6, fix.solver


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args()
    print("landmarks  no attitude (us, solver)      attitude (us, solver)")
    for n in (1, 2, 4, 8):
        a_us, a_solver = time_fixes(n, False, args.repeats)
        b_us, b_solver = time_fixes(n, True, args.repeats)
        print(f"{n:9d}  {a_us:8.0f}  {a_solver:18s}  {b_us:8.0f}  {b_solver}")


if __name__ == "__main__":
    main()
