"""Closed attitude loop: does the autopilot's attitude, made of our fixes, run away?

Run: PYTHONPATH=. python benchmarks/pose_attitude_loop.py [--seed N [N ...]] [--seconds S]
    [--position-feedback G]

Flies the geometric flights that use the autopilot's attitude with the loop of
``tracker.pose.attitude_loop`` closed (the autopilot's attitude error starts at 5 deg yaw,
drifts 2 deg/min, moves to each fix's attitude and grows with each fix's position error
seen from the landmarks), for three solver set-ups:

* ``checked 2.5/5``: the default prior (2.5 deg roll/pitch, 5 deg yaw), checked against the
  landmarks' own attitude (issue 19);
* ``trusted 0.2/1``: the prior as it was before issue 19, used as stated;
* ``checked 0.2/1``: the old sigmas, checked.

Printed per flight, set-up and seed: fixes/frames, the autopilot's attitude error (largest
axis: at the end, and its maximum after the first 10 s), the fixes' position error (median,
maximum), the share of fixes with NEES inside the 95 % bounds, and how many fixes rejected
the prior.  A runaway shows as an attitude error that grows to tens of degrees, fixes lost
(the landmarks no longer fit the attitude) and a NEES far outside.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from tracker.pose.attitude_loop import LoopConfig, fly_loop
from tracker.pose.scenarios import NEES_HIGH_3DOF, NEES_LOW_3DOF, scenarios

FLIGHTS = ("hover_wall_attitude", "two_landmarks_attitude_corners", "survey")
SETUPS = {
    "checked 2.5/5": LoopConfig(),
    "trusted 0.2/1": LoopConfig(prior_sigma_deg=(0.2, 1.0), check=False),
    "checked 0.2/1": LoopConfig(prior_sigma_deg=(0.2, 1.0)),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--position-feedback", type=float, default=0.5)
    args = parser.parse_args()
    by_name = {s.name: s for s in scenarios()}
    print("| flight | set-up | seed | fixes/frames | att. error end / max deg | "
          "pos. error median / max m | NEES inside 95 % | prior rejected |")
    print("|---|---|---|---|---|---|---|---|")
    for name in FLIGHTS:
        flight = replace(by_name[name], duration_s=args.seconds)
        for label, setup in SETUPS.items():
            loop = replace(setup, position_feedback=args.position_feedback)
            for seed in args.seed:
                steps = fly_loop(flight, loop, seed)
                errors = [s.position_error_m for s in steps if s.position_error_m is not None]
                nees = [s.nees for s in steps if s.nees is not None]
                inside = np.mean([NEES_LOW_3DOF <= n <= NEES_HIGH_3DOF for n in nees]) \
                    if nees else float("nan")
                late = [s.attitude_error_deg for s in steps if s.t_s >= 10.0]
                rejected = sum(s.prior == "rejected" for s in steps)
                med, worst = (np.median(errors), max(errors)) if errors else (np.nan, np.nan)
                print(f"| {name} | {label} | {seed} | {len(errors)}/{len(steps)} | "
                      f"{steps[-1].attitude_error_deg:.1f} / {max(late):.1f} | "
                      f"{med:.3f} / {worst:.2f} | {inside:.3f} | {rejected} |")


if __name__ == "__main__":
    main()
