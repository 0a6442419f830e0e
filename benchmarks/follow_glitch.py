"""How the perception reacts to one frame whose camera pose is a few cm off.

Run: ``PYTHONPATH=. python benchmarks/follow_glitch.py [--glitch-m 0.08] [--frame 40]``.

The survey scenario at 15 fps from 3 s for 6 s, rendered by the simulator, processed by a
fresh perception; one frame is rendered ``--glitch-m`` metres south of the truth (what a
follow-mode frame looks like when a truth sample was read late).  Prints the fix count,
median and largest error against the truth, without and with the glitch.  Found while
building follow mode: an 8 cm glitch on one frame left the fixes ~3 m off for the rest of
the run (the fix gate keeps the wrong, self-consistent solution).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np

from companion.demo import map_landmarks
from companion.perception import Perception
from companion.settings import SIM_LAYERS, load_settings
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from tracker.pose.types import PoseFix


def run(glitch_m: float, glitch_frame: int, fps: float = 15.0) -> list[float]:
    sim = Simulator(replace(load_scenario("survey"), fps=fps))
    settings = load_settings(shipped=SIM_LAYERS)
    landmarks, references = map_landmarks(sim)
    perception = Perception(sim.scenario.camera, landmarks, references,
                            config=settings.perception, tracker_config=settings.tracker,
                            pose_config=settings.pose, acquire_config=settings.acquire,
                            gate_config=settings.fixgate)
    errors = []
    for k in range(round(6.0 * fps)):
        t_s = 3.0 + k / fps
        truth = sim.state_at(t_s)
        d = glitch_m if k == glitch_frame else 0.0
        n, e, down = truth.position_ned_m
        shown = replace(truth, position_ned_m=(n - d, e, down))
        rendered = sim.renderer.render(shown, sim.effects.world_quads(t_s))
        image = sim.effects.apply(rendered.image, t_s, k, rendered.boxes)
        frame = Frame(k, round(t_s * 1e6), image, "sim0")
        result = perception.process(frame)
        perception.housekeeping(frame)
        if isinstance(result.fix, PoseFix):
            errors.append(math.dist(result.fix.position_ned_m, truth.position_ned_m))
    return errors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--glitch-m", type=float, default=0.08)
    parser.add_argument("--frame", type=int, default=40)
    args = parser.parse_args()
    for glitch in (0.0, args.glitch_m):
        errors = run(glitch, args.frame)
        print(f"glitch {glitch:.3f} m at frame {args.frame}: {len(errors)} fixes, median "
              f"{np.median(errors):.3f} m, max {max(errors):.3f} m")


if __name__ == "__main__":
    main()
