"""The simulator: one scenario's world, trajectory, camera, effects and range finder."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from companion import __version__
from companion.core.frames import ImageU8
from companion.core.stream_format import FrameTruth, StreamMeta
from companion.errors import ConfigError
from companion.sim.effects import EffectStack
from companion.sim.rangefinder import RangeFinder
from companion.sim.render import Renderer
from companion.sim.scenario import ScenarioConfig, landmarks_path
from companion.sim.trajectory import KinematicState, Trajectory
from companion.sim.world import World, load_landmark_map
from mavlink_bridge.vehicle import TruthFn, VehicleState

RANGE_STREAM = 7919  # keeps range-finder randomness apart from effect randomness


class Simulator:
    """Renders frame ``index`` (time ``index / fps``) with its truth, deterministically.

    :meth:`state_at` is the callable to hand to the fake autopilot: the camera and the
    autopilot then report the same flight.
    """

    def __init__(self, scenario: ScenarioConfig) -> None:
        self.scenario = scenario
        origin = scenario.origin.to_origin()
        landmarks = load_landmark_map(landmarks_path(scenario), origin, scenario.seed)
        self.world = World(landmarks, scenario.world, scenario.seed)
        self.trajectory = Trajectory(scenario.trajectory)
        self.renderer = Renderer(scenario.camera, self.world)
        try:
            self.effects = EffectStack(scenario.effects, self.world, scenario.seed)
        except KeyError as err:
            where = scenario.path or scenario.name
            raise ConfigError(f"{where}: effects: unknown landmark_id {err}") from None
        self.rangefinder = RangeFinder(scenario.rangefinder, self.world)

    @property
    def fps(self) -> float:
        """Frames per second of the simulated camera."""
        return self.scenario.fps

    def reference_images(self) -> dict[str, ImageU8]:
        """The appearance reference (texture) of each landmark that has one."""
        return {lm.landmark_id: lm.quad.texture for lm in self.world.landmarks
                if lm.quad.texture is not None}

    def state_at(self, t_s: float) -> KinematicState:
        """The vehicle state at ``t_s`` scenario seconds (shared with the fake autopilot)."""
        return self.trajectory.state_at(t_s)

    def autopilot_truth(self, t_s: float) -> VehicleState:
        """Truth for the fake autopilot at ``t_s``: hand ``simulator.autopilot_truth`` (a
        ``mavlink_bridge.vehicle.TruthFn``) to ``FakeAutopilot(config, truth=...)``.

        ``range_m`` is the range finder's reading (deterministic per millisecond and seed);
        a dropout or no return reads ``max_range_m + 1``: out of range, which is how a
        DISTANCE_SENSOR says "no reading".
        """
        state = self.state_at(t_s)
        rng = np.random.default_rng([self.scenario.seed, round(t_s * 1000.0), RANGE_STREAM])
        reading = self.rangefinder.measure(state, rng)
        range_m = self.rangefinder.config.max_range_m + 1.0 if reading is None else reading
        return VehicleState(t_s, state.position_ned_m, state.velocity_ned_m_s,
                              state.attitude_rpy_rad, range_m)

    @property
    def truth_fn(self) -> TruthFn:
        """:meth:`autopilot_truth` typed as the fake autopilot's ``TruthFn``."""
        return self.autopilot_truth

    def render(self, index: int, t_s: float | None = None) -> tuple[ImageU8, FrameTruth]:
        """Frame ``index`` at ``t_s`` (default ``index / fps``) and its truth."""
        t = index / self.fps if t_s is None else t_s
        return self.render_state(self.state_at(t), index, t)

    def render_state(self, state: KinematicState, index: int, t_s: float
                     ) -> tuple[ImageU8, FrameTruth]:
        """Frame ``index`` seen from ``state`` (scripted or followed), effects at ``t_s``."""
        rendered = self.renderer.render(state, self.effects.world_quads(t_s))
        image = self.effects.apply(rendered.image, t_s, index, rendered.boxes)
        rng = np.random.default_rng([self.scenario.seed, index, RANGE_STREAM])
        range_m = self.rangefinder.measure(state, rng)
        boxes = tuple(
            replace(b, occluded_frac=self.effects.occluded_frac(b.landmark_id, t_s))
            for b in rendered.boxes
        )
        return image, FrameTruth(boxes, rendered.pose, rendered.camera, range_m)

    def stream_meta(self, fps: float | None = None) -> StreamMeta:
        """``stream.toml`` contents for a recording of this scenario."""
        s = self.scenario
        provenance = {
            "generator": f"landmark-companion {__version__} synth",
            "scenario": s.name,
            "scenario_file": s.path,
            "seed": s.seed,
            "landmarks": str(landmarks_path(s)),
        }
        return StreamMeta(
            fps=fps or s.fps,
            camera=s.camera,
            camera_id=s.camera_id,
            origin=s.origin.to_origin(),
            provenance=provenance,
        )

    def with_overrides(
        self, seconds: float | None = None, fps: float | None = None, seed: int | None = None
    ) -> Simulator:
        """A simulator for the same scenario with other duration, rate or seed."""
        s = self.scenario
        return Simulator(
            replace(s, seconds=seconds or s.seconds, fps=fps or s.fps,
                    seed=s.seed if seed is None else seed)
        )
