"""Perception over a rendered scenario, against the simulated truth (no MAVLink, no clock).

Renders every frame of a scenario, runs ``companion.perception.Perception`` on it with the
true attitude (as the autopilot would give it), and prints: fixes, position RMSE overall
and by the number of landmarks used, RMSE as a share of the distance to them, the share of
fixes whose NEES lies inside the 95 % chi-square bounds, and the per-frame time of the
critical path (``process``) and of ``housekeeping``.

    PYTHONPATH=. python benchmarks/perception_survey.py [--scenario survey] [--frames 900]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import cv2
import numpy as np

from companion.demo import map_landmarks
from companion.perception import Perception, SideSensors
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from tracker.pose.config import PoseConfig
from tracker.pose.types import AttitudeSample, PoseFix

NEES_LOW, NEES_HIGH = 0.2158, 9.348  # chi-square, 3 DOF, 2.5 % and 97.5 %


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="survey")
    parser.add_argument("--frames", type=int, default=900)
    parser.add_argument("--pixel-sigma", type=float, default=0.15)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    sim = Simulator(dataclasses.replace(load_scenario(args.scenario),
                                        seconds=args.frames / 30.0))
    landmarks, references = map_landmarks(sim)
    by_id = {lm.landmark_id: lm for lm in landmarks}

    def sensors(t_us: int) -> SideSensors:
        s = sim.state_at(t_us / 1e6)
        return SideSensors(attitude=AttitudeSample(t_us, *s.attitude_rpy_rad))

    perception = Perception(sim.scenario.camera, landmarks, references, sensors=sensors,
                            pose_config=PoseConfig(pixel_sigma_px=args.pixel_sigma))
    process_ms, house_ms, errors, dists, nees = [], [], [], [], []
    by_count: dict[int, list[float]] = {}
    for i in range(args.frames):
        image, _ = sim.render(i)
        frame = Frame(i, round(i * 1e6 / sim.fps), image)
        t0 = time.perf_counter()
        result = perception.process(frame)
        t1 = time.perf_counter()
        perception.housekeeping(frame)
        process_ms.append((t1 - t0) * 1e3)
        house_ms.append((time.perf_counter() - t1) * 1e3)
        if not isinstance(result.fix, PoseFix):
            continue
        truth = np.asarray(sim.state_at(i / sim.fps).position_ned_m)
        err_v = np.asarray(result.fix.position_ned_m) - truth
        errors.append(float(np.linalg.norm(err_v)))
        by_count.setdefault(len(result.fix.landmark_ids), []).append(errors[-1])
        dists.append(float(np.mean([np.linalg.norm(truth - by_id[i].position_ned_m)
                                    for i in result.fix.landmark_ids])))
        cov = np.asarray(result.fix.covariance)[:3, :3]
        nees.append(float(err_v @ np.linalg.solve(cov, err_v)))
    rmse = float(np.sqrt(np.mean(np.square(errors))))
    share = np.mean((np.array(nees) > NEES_LOW) & (np.array(nees) < NEES_HIGH))
    print(f"scenario {args.scenario}: {len(errors)} fixes in {args.frames} frames")
    print(f"position RMSE {rmse:.4f} m at a mean {np.mean(dists):.2f} m "
          f"({100 * rmse / np.mean(dists):.2f} %); median error {np.median(errors):.4f} m")
    for n, errs in sorted(by_count.items()):
        r = float(np.sqrt(np.mean(np.square(errs))))
        print(f"  {n} landmark(s): {len(errs)} fixes, RMSE {r:.4f} m")
    print(f"NEES inside the 95 % bounds: {100 * share:.1f} % (median {np.median(nees):.2f}, "
          f"ideal 2.37)")
    print(f"process ms median {np.median(process_ms):.2f} p99 {np.percentile(process_ms, 99):.2f}; "
          f"housekeeping ms median {np.median(house_ms):.2f} p99 "
          f"{np.percentile(house_ms, 99):.2f}")


if __name__ == "__main__":
    main()
