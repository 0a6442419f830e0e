"""A simulated laser range finder: distance along a body axis to the ground or a wall."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.sim.trajectory import KinematicState
from companion.sim.world import Quad, World
from tracker.geometry import FloatArray


@dataclass(frozen=True)
class RangeFinderConfig:
    """Beam along ``axis_body`` (FRD; (0, 0, 1) points down), range limits, noise, dropouts."""

    enabled: bool = True
    axis_body: tuple[float, float, float] = (0.0, 0.0, 1.0)
    min_range_m: float = field(default=0.2, metadata={"ge": 0})
    max_range_m: float = field(default=40.0, metadata={"gt": 0})
    noise_m: float = field(default=0.02, metadata={"ge": 0})
    dropout_prob: float = field(default=0.02, metadata={"ge": 0, "le": 1})


def ray_quad_distance(origin: FloatArray, direction: FloatArray, quad: Quad) -> float | None:
    """Distance along a unit ray to a rectangle, or None when it misses.

    t = n.(p0 - o) / n.d; the hit is inside when its coordinates along the two edges from
    TL lie within the edge lengths.
    """
    c = quad.corners_ned
    n = quad.normal_ned
    denom = float(n @ direction)
    if abs(denom) < 1e-9:
        return None
    t = float(n @ (c[0] - origin)) / denom
    if t <= 0:
        return None
    hit = origin + t * direction - c[0]
    u, v = c[1] - c[0], c[3] - c[0]
    a, b = float(hit @ u) / float(u @ u), float(hit @ v) / float(v @ v)
    return t if 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0 else None


class RangeFinder:
    """Answers :meth:`measure` for the fake autopilot's DISTANCE_SENSOR."""

    def __init__(self, config: RangeFinderConfig, world: World) -> None:
        axis = np.asarray(config.axis_body, dtype=np.float64)
        norm = float(np.linalg.norm(axis))
        if norm == 0.0:
            raise ValueError("axis_body: expected a non-zero vector")
        self.config = config
        self.axis_body = axis / norm
        self.world = world
        self._quads = [*world.facades, *(lm.quad for lm in world.landmarks)]

    def true_range(self, state: KinematicState) -> float | None:
        """Exact distance to the nearest surface along the beam (no noise, no limits)."""
        origin = np.asarray(state.position_ned_m, dtype=np.float64)
        d = state.r_ned_body @ self.axis_body
        hits = [t for q in self._quads if (t := ray_quad_distance(origin, d, q)) is not None]
        if d[2] > 1e-9:  # the infinite ground plane: t = (ground_down - down) / d_z
            t = (self.world.config.ground_down_m - origin[2]) / d[2]
            if t > 0:
                hits.append(float(t))
        return min(hits) if hits else None

    def measure(self, state: KinematicState, rng: np.random.Generator) -> float | None:
        """A reading with noise, or None for a dropout or nothing within range."""
        cfg = self.config
        if not cfg.enabled or rng.uniform() < cfg.dropout_prob:
            return None
        true = self.true_range(state)
        if true is None:
            return None
        value = true + float(rng.normal(0.0, cfg.noise_m)) if cfg.noise_m > 0 else true
        return value if cfg.min_range_m <= value <= cfg.max_range_m else None
