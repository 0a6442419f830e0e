"""The geometric flights' Cramer-Rao bound against the solver's measured RMSE.

Run: PYTHONPATH=. python benchmarks/pose_crb.py [--seed N [N ...]] [--check]

For each flight of ``tracker.pose.scenarios.reference_flights`` (calibrated noise): the bound is
the position part of ``(J^T J)^-1``, the whitened Jacobian of every pixel and prior at the
*true* pose -- the solver's own covariance for noise-free inputs (which it solves exactly),
so it is what any unbiased estimator's error covariance is at least, for these landmarks,
this camera and these noise sigmas.  Printed per flight: the RMS over frames of
``sqrt(trace P_pos)`` in metres and as a share of the mean distance to the landmarks,
beside the RMSE the solver reached over the seeds (all fixes; ratio ~1: the solver reaches
the bound).  Where the bound itself is above 0.5 % of the distance, no unbiased solver can
meet issue 6's 0.5 % on that flight: only other inputs (landmarks spread in depth, more of
them, the attitude, finer corners) can.  ``--check`` exits 1 when the RMSE is more than
15 % above the bound on any flight (the solver no longer reaching it).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from tracker.pose.scenarios import (
    Scenario,
    fly,
    reference_flights,
    run_scenario,
    solve_frame,
    solver_config,
)
from tracker.pose.simulate import SensorNoise
from tracker.pose.types import PoseFix

#: RMSE / bound above this fails ``--check``.
MAX_RATIO = 1.15

#: Noise-free measurements: corners, centres, attitude, altitude and range all exact.
EXACT = SensorNoise(pixel_sigma_px=0.0, centre_sigma_px=0.0, roll_pitch_sigma_rad=0.0,
                    yaw_sigma_rad=0.0, altitude_sigma_m=0.0, range_sigma_m=0.0)


def bound(scenario: Scenario) -> tuple[float, float]:
    """(RMS over frames of sqrt(trace P_pos) at the truth, mean distance to the landmarks
    used) for ``scenario``: noise-free inputs, solved with the scenario's sigmas."""
    cfg = solver_config(scenario)
    n = scenario.noise
    traces, dists = [], []
    for frame in fly(replace(scenario, noise=EXACT, misname_rate=0.0),
                     np.random.default_rng(0)):
        att = replace(frame.attitude, roll_pitch_sigma_rad=n.roll_pitch_sigma_rad,
                      yaw_sigma_rad=n.yaw_sigma_rad)
        alt = replace(frame.altitude, sigma_m=n.altitude_sigma_m)
        laser = None if frame.laser is None else replace(frame.laser, sigma_m=n.range_sigma_m)
        frame = replace(frame, attitude=att, altitude=alt, laser=laser)
        fix = solve_frame(replace(scenario, unlabelled=False), frame, cfg)
        if not isinstance(fix, PoseFix):
            continue
        assert np.allclose(fix.position_ned_m, frame.true_position_ned_m, atol=1e-6)
        traces.append(float(np.trace(fix.covariance[:3, :3])))
        used = [lm for lm in scenario.landmarks if lm.landmark_id in fix.landmark_ids]
        dists.append(float(np.mean([np.linalg.norm(np.subtract(lm.position_ned_m,
                                                                frame.true_position_ned_m))
                                    for lm in used])))
    return float(np.sqrt(np.mean(traces))), float(np.mean(dists))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, nargs="+", default=list(range(1, 11)))
    parser.add_argument("--check", action="store_true", help=f"fail above {MAX_RATIO} x bound")
    args = parser.parse_args()
    print(f"seeds {args.seed[0]}-{args.seed[-1]} ({len(args.seed)}); noise as calibrated "
          "(SensorNoise defaults)\n")
    print("| flight | mean dist m | bound m | bound % of dist | RMSE m (all fixes, all seeds) "
          "| RMSE % of dist | RMSE / bound |")
    print("|---|---|---|---|---|---|---|")
    failed = []
    for i, sc in enumerate(reference_flights()):  # i: the seeds pose_accuracy.py uses
        if sc.misname_rate > 0 or sc.unlabelled:
            continue  # the same geometry as their plain flight; outliers are another matter
        crb, dist = bound(sc)
        sq, n = 0.0, 0
        for seed in args.seed:
            r = run_scenario(sc, np.random.default_rng(seed * 100 + i))
            sq += r.rmse_m**2 * r.fixes
            n += r.fixes
        rmse = float(np.sqrt(sq / n))
        ratio = rmse / crb
        print(f"| {sc.name} | {dist:.1f} | {crb:.4f} | {100 * crb / dist:.2f} % | {rmse:.4f} | "
              f"{100 * rmse / dist:.2f} % | {ratio:.2f} |")
        if ratio > MAX_RATIO:
            failed.append(sc.name)
    if args.check and failed:
        print(f"\nRMSE above {MAX_RATIO} x the bound: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
