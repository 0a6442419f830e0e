"""One landmark in view for 10 s (issue 19): the fixes go on, and their covariance is honest.

On ArduPilot SITL's square, the leg from (6, 0) to (6, 6) sees one landmark without
corners, and the companion gave no fix for 6-7 s ("one landmark without corners and no
attitude: pose unobservable"): the EKF dropped its position.  Here the companion hovers
10 m in front of wall-04 alone (config/scenarios/one_landmark.toml) with the fake
autopilot's attitude (its default EKF error, 1 deg / 3 deg, stated with the deployment
default 2.5 deg / 5 deg), height
(LOCAL_POSITION_NED) and, when configured, a forward
range finder (DISTANCE_SENSOR orientation 0) -- the side sensors of
:class:`companion.sensors.SensorHistory`:

* (``corners``, the plate's corners with the attitude: not a case, see below);
* ``box``: corners off (a plate too small for them): its box centre's bearing with the
  attitude, the height and the box's size (``altitude_bearing``);
* ``box+laser``: the same with the range finder (``range_bearing``).

Each proves that the only landmark in view is wall-04 for at least 10 s, that fixes then
come on >= 80 % of the frames with no gap over 1 s, and that the NEES of >= 90 % of them
stays below the 95 % bound of chi-square with 3 DOF (7.815): the covariance says how weak
they are.  (One-sided: the fake autopilot's attitude error is smaller than the 2.5 deg /
5 deg the solver is told, so the box fixes' errors are inside their sigma; a
covariance too cautious is not the danger, one that hides the error is.)

The corner case does not hold: one plate's corners are not independent:
they fixed its tilt to a claimed 0.06-0.09 m in height and were 0.2-0.6 m off (NEES median
~40-50; the alignment moves a plate's outline as a whole, docs/pose.md, "One plate's
outline").  Not a case here: with ``pose.one_plate_outline_sigma_rel = 3`` (opt-in, off in
both shipped layers, docs/decisions.md) the NEES share was 1.00 in two runs and 0.835 in a
third (median 3.5): not reliably honest, so issue 19 stays open on it.  With it, the outline's
scale, aspect, shear and perspective carry a common error and the tilt's covariance says
how weak one plate is.  Before issue 19 the exact attitude, taken as near-certain, pinned
the tilt and hid it (the issue's "parked 0.40 m off truth").
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from companion.sim.scenario import load_scenario
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig
from sitl_tests.harness import Flight, sitl_settings

SECONDS = 14.0
WINDOW_S = (3.0, 13.5)  # after acquisition; 10.5 s
NEES_95_3DOF = 7.815  # chi2.ppf(0.95, 3)
#: settings, range finder, the solvers expected (size_bearing: a frame whose height sample
#: came late; altitude_bearing with the laser: a dropout or the beam off the plate)
CASES = {
    "box": ({"refine_corners": False}, False, ("altitude_bearing", "size_bearing")),
    "box+laser": ({"refine_corners": False}, True,
                  ("range_bearing", "altitude_bearing", "size_bearing")),
}


#: ``SITL_SEEDS=0,1,2``: the scenario's and the fake's seeds (noise, attitude error); by
#: default the scenario's own (3) and the fake's (0)
SEEDS = [int(v) for v in os.environ["SITL_SEEDS"].split(",")] if "SITL_SEEDS" in os.environ \
    else [None]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("case", ["box", "box+laser"])
async def test_one_landmark_for_10_s_gives_honest_fixes(tmp_path: Path, case: str,
                                                        seed: int | None) -> None:
    perception, laser, solvers = CASES[case]
    settings = sitl_settings(tmp_path, deployment_prior=True, perception=perception,
                             pose={"rangefinder": laser})
    # the scenario's laser: forward
    fake = FakeAutopilotConfig(rangefinder_orientation=0, seed=seed or 0)
    scenario = load_scenario("one_landmark")
    scenario = scenario if seed is None else dataclasses.replace(scenario, seed=seed)
    flight = await Flight(scenario, SECONDS, settings, autopilot=fake).run()
    window = [f for f in flight.frames if WINDOW_S[0] <= f.t_s <= WINDOW_S[1]]
    assert window[-1].t_s - window[0].t_s >= 10.0
    seen = {lid for f in window for lid, share in f.visible.items() if share > 0.0}
    assert seen == {"wall-04"}, f"in view: {seen}"
    fixes = [f for f in window if f.fix_ned_m is not None]
    share = len(fixes) / len(window)
    times = [WINDOW_S[0], *[f.t_s for f in fixes], WINDOW_S[1]]
    gap = float(max(np.diff(times)))
    used = {f.fix_solver for f in fixes}
    nees = [f.fix_nees for f in fixes if f.fix_nees is not None]
    inside = float(np.mean([n <= NEES_95_3DOF for n in nees]))
    errors = [float(np.linalg.norm(np.subtract(f.fix_ned_m, f.truth_ned_m))) for f in fixes]
    print(f"{case} seed {seed}: {len(fixes)}/{len(window)} frames with a fix, longest gap "
          f"{gap:.2f} s, "
          f"solvers {sorted(used)}, NEES below the 95 % bound {inside:.3f} (median "
          f"{np.median(nees):.1f}), "
          f"error median {np.median(errors):.3f} m, max {max(errors):.3f} m")
    assert share >= 0.8 and gap <= 1.0
    assert used <= set(solvers), used
    assert inside >= 0.9
