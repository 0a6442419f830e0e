"""Accuracy and covariance consistency of the pose solver on simulated flights.

Run: PYTHONPATH=. python benchmarks/pose_accuracy.py [--seed N [N ...]] [--check]
[--pixel-sigma PX] [--centre-sigma PX]

For every scenario of :mod:`tracker.pose.scenarios` prints the fixes, the position RMSE
against the simulated truth (all fixes, and the fixes from two or more landmarks as a
percentage of their mean distance), the RMS 1-sigma the covariances promised, and the
share of fixes whose 3-DOF position NEES lies inside the 95 % chi-square bounds
[0.2158, 9.348].  ``--check`` exits 1 when a committed baseline is missed (see BASELINE).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from tracker.pose.scenarios import Scenario, ScenarioResult, reference_flights, run_scenario

#: Regression gates, per scenario: (largest multi-landmark RMSE in % of distance or None,
#: smallest share of fixes with NEES inside the 95 % bounds), for the calibrated noise
#: (SensorNoise defaults: corners 0.3 px, box centres 1 px).  The 0.5 % gates are issue 6's
#: target; the looser ones are geometry-limited flights (RMSE = the promised sigma), set
#: above their measured range over seeds 1-10 (docs/pose.md, "Measured") to catch a loss.
BASELINE: dict[str, tuple[float | None, float]] = {
    "hover_wall": (1.5, 0.9),  # 1.14-1.30 %, NEES share 0.920-0.963
    "hover_wall_attitude": (0.5, 0.9),  # 0.29-0.31 %
    "hover_street": (0.5, 0.9),
    "survey": (0.5, 0.9),
    "single_landmark_laser": (None, 0.9),
    "two_landmarks_attitude": (2.5, 0.9),  # 1.74-2.00 % (box centres only)
    "two_landmarks_attitude_corners": (1.0, 0.9),  # 0.78-0.82 %
    "two_landmarks_attitude_yaw0.25": (1.0, 0.9),  # 0.63-0.68 % (box centres only)
    "hover_street_unlabelled": (0.5, 0.9),
    "survey_unlabelled": (0.5, 0.9),
    "hover_street_misnamed": (0.5, 0.9),  # 0.17-0.26 %
    "survey_misnamed": (0.5, 0.9),
}


def _row(r: ScenarioResult) -> str:
    pct = f"{r.rmse_multi_pct:.2f} %" if r.fixes_multi else "-"
    ok = (
        "yes" if r.fixes_multi and r.rmse_multi_pct <= 0.5 else ("-" if not r.fixes_multi else "no")
    )
    solvers = ", ".join(f"{k} {v}" for k, v in sorted(r.solvers.items()))
    return (
        f"| {r.name} | {r.fixes}/{r.frames} | {r.mean_distance_m:.1f} | {r.rmse_m:.3f} | "
        f"{r.predicted_rms_m:.3f} | {pct} | {ok} | {r.nees_inside:.3f} | {r.nees_mean:.2f} | "
        f"{solvers} | {r.dropped} |"
    )


def _runs(pixel_sigma: float | None, centre_sigma: float | None) -> list[Scenario]:
    """The reference scenarios plus the two-landmark pair with a 0.25 deg yaw prior;
    ``pixel_sigma`` / ``centre_sigma`` replace the corner / box-centre noise of every flight
    (the solver's sigmas follow, see ``solver_config``)."""
    runs = reference_flights()
    if pixel_sigma is not None:
        runs = [replace(s, noise=replace(s.noise, pixel_sigma_px=pixel_sigma)) for s in runs]
    if centre_sigma is not None:
        runs = [replace(s, noise=replace(s.noise, centre_sigma_px=centre_sigma)) for s in runs]
    return runs


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, nargs="+", default=[1], help="one table per seed")
    parser.add_argument("--check", action="store_true", help="fail below the baseline")
    parser.add_argument(
        "--pixel-sigma",
        type=float,
        default=None,
        help="corner noise (px) of every flight instead of the calibrated SensorNoise default",
    )
    parser.add_argument("--centre-sigma", type=float, default=None, help="box-centre noise (px)")
    args = parser.parse_args()
    if args.check and (args.pixel_sigma is not None or args.centre_sigma is not None):
        parser.error("--check gates the calibrated noise: leave out --pixel-sigma/--centre-sigma")
    runs = _runs(args.pixel_sigma, args.centre_sigma)
    failed = []
    for seed in args.seed:
        n = runs[0].noise
        print(
            f"seed {seed}, noise: corners {n.pixel_sigma_px} px, centres {n.centre_sigma_px} px\n"
        )
        print(
            "| scenario | fixes/frames | mean dist m | RMSE m | promised 1-sigma m | "
            "RMSE (2+ landmarks) | <= 0.5 % | NEES inside 95 % | mean NEES | solvers | dropped |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for i, sc in enumerate(runs):
            r = run_scenario(sc, np.random.default_rng(seed * 100 + i))
            print(_row(r))
            max_pct, min_inside = BASELINE[r.name]
            if (
                max_pct is not None and not r.rmse_multi_pct <= max_pct
            ) or r.nees_inside < min_inside:
                failed.append(f"{r.name} (seed {seed})")
        print()
    if args.check and failed:
        print(f"below baseline: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
