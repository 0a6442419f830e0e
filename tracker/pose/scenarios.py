"""Scripted simulated flights for the pose solver and their accuracy statistics.

Each scenario is a landmark field, a camera, a trajectory and which side sensors the solver
gets.  :func:`run_scenario` flies it and compares every fix with the truth:

* position RMSE, and the mean distance to the landmarks used;
* NEES ``e^T P_pos^-1 e`` of the 3-D position, and the share of fixes inside the two-sided
  95 % chi-square bounds for 3 DOF: ``chi2.ppf(0.025, 3) = 0.2158``,
  ``chi2.ppf(0.975, 3) = 9.348`` (hard-coded: no scipy dependency).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import FloatArray
from tracker.pose.config import PoseConfig
from tracker.pose.simulate import SensorNoise, SimFrame, Trajectory, simulate_frame
from tracker.pose.solve import solve_pose
from tracker.pose.types import MapLandmark, NoFix, PoseFix

NEES_LOW_3DOF = 0.2158  # chi2.ppf(0.025, 3)
NEES_HIGH_3DOF = 9.348  # chi2.ppf(0.975, 3)


@dataclass(frozen=True)
class Scenario:
    """A simulated flight and the inputs the solver is given."""

    name: str
    landmarks: tuple[MapLandmark, ...]
    camera: CameraModel
    trajectory: Trajectory
    duration_s: float
    rate_hz: float = 10.0
    noise: SensorNoise = field(default_factory=SensorNoise)
    use_corners: bool = True
    use_attitude: bool = False
    use_altitude: bool = False
    laser_axis_body: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class ScenarioResult:
    """Accuracy of one flown scenario."""

    name: str
    frames: int
    fixes: int
    fixes_multi: int  # fixes from two or more landmarks
    rmse_m: float
    rmse_multi_m: float
    mean_distance_m: float
    mean_distance_multi_m: float
    nees_inside: float  # share of fixes with NEES inside the 95 % bounds
    nees_mean: float
    solvers: dict[str, int]
    no_fix_reasons: dict[str, int]

    @property
    def rmse_multi_pct(self) -> float:
        """RMSE of the multi-landmark fixes as a percentage of their mean distance."""
        if self.fixes_multi == 0:
            return float("nan")
        return 100.0 * self.rmse_multi_m / self.mean_distance_multi_m


def solver_config(scenario: Scenario, base: PoseConfig | None = None) -> PoseConfig:
    """The solver config whose noise model matches the scenario's sensors."""
    cfg = base or PoseConfig()
    n = scenario.noise
    extra = float(np.sqrt(max(n.centre_sigma_px**2 - n.pixel_sigma_px**2, 1e-6)))
    return replace(cfg, pixel_sigma_px=n.pixel_sigma_px, centre_sigma_px=extra)


def solve_frame(scenario: Scenario, frame: SimFrame, config: PoseConfig) -> PoseFix | NoFix:
    """Solve one simulated frame with the inputs the scenario grants the solver."""
    obs = frame.observations
    if not scenario.use_corners:
        obs = tuple(replace(o, corners_px=None) for o in obs)
    return solve_pose(
        obs,
        scenario.landmarks,
        scenario.camera,
        frame.time_us,
        attitude=frame.attitude if scenario.use_attitude else None,
        altitude=frame.altitude if scenario.use_altitude else None,
        laser=frame.laser,
        config=config,
    )


def fly(scenario: Scenario, rng: np.random.Generator) -> list[SimFrame]:
    """Every simulated frame of ``scenario``."""
    n_frames = int(scenario.duration_s * scenario.rate_hz)
    return [
        simulate_frame(
            scenario.landmarks,
            scenario.camera,
            scenario.trajectory,
            i / scenario.rate_hz,
            rng,
            scenario.noise,
            scenario.laser_axis_body,
        )
        for i in range(n_frames)
    ]


def run_scenario(
    scenario: Scenario, rng: np.random.Generator, config: PoseConfig | None = None
) -> ScenarioResult:
    """Fly ``scenario`` and score every fix against the truth."""
    cfg = solver_config(scenario, config)
    frames = fly(scenario, rng)
    errs, dists, nees, multi, solvers, reasons = [], [], [], [], Counter[str](), Counter[str]()
    for frame in frames:
        fix = solve_frame(scenario, frame, cfg)
        if not isinstance(fix, PoseFix):
            reasons[fix.reason.split(":")[0]] += 1
            continue
        solvers[fix.solver] += 1
        e = np.asarray(fix.position_ned_m) - frame.true_position_ned_m
        errs.append(e)
        nees.append(float(e @ np.linalg.solve(fix.covariance[:3, :3], e)))
        dists.append(_mean_distance(scenario.landmarks, fix, frame.true_position_ned_m))
        multi.append(len(fix.landmark_ids) >= 2)
    return _summarise(scenario.name, len(frames), errs, dists, nees, multi, solvers, reasons)


def _mean_distance(landmarks: tuple[MapLandmark, ...], fix: PoseFix, p: FloatArray) -> float:
    used = [lm for lm in landmarks if lm.landmark_id in fix.landmark_ids]
    return float(np.mean([np.linalg.norm(np.asarray(lm.position_ned_m) - p) for lm in used]))


def _summarise(
    name: str,
    n_frames: int,
    errs: list[FloatArray],
    dists: list[float],
    nees: list[float],
    multi: list[bool],
    solvers: Counter[str],
    reasons: Counter[str],
) -> ScenarioResult:
    e2 = np.array([float(e @ e) for e in errs]) if errs else np.zeros(0)
    m = np.array(multi, dtype=bool)
    d = np.array(dists)
    ne = np.array(nees)

    def rmse(sel: np.ndarray) -> float:
        return float(np.sqrt(np.mean(e2[sel]))) if np.any(sel) else float("nan")

    inside = (ne >= NEES_LOW_3DOF) & (ne <= NEES_HIGH_3DOF)
    return ScenarioResult(
        name=name,
        frames=n_frames,
        fixes=len(errs),
        fixes_multi=int(m.sum()),
        rmse_m=rmse(np.ones(len(errs), dtype=bool)),
        rmse_multi_m=rmse(m),
        mean_distance_m=float(d.mean()) if len(d) else float("nan"),
        mean_distance_multi_m=float(d[m].mean()) if m.any() else float("nan"),
        nees_inside=float(inside.mean()) if len(ne) else float("nan"),
        nees_mean=float(ne.mean()) if len(ne) else float("nan"),
        solvers=dict(solvers),
        no_fix_reasons=dict(reasons),
    )


# --- the scenarios -------------------------------------------------------------------------

FORWARD_CAMERA = CameraModel()
DOWN_CAMERA = CameraModel(mount_rpy_deg=(0.0, -90.0, 0.0))


def _sign(
    lid: str, n: float, e: float, d: float, facing: float | None, w: float, h: float
) -> MapLandmark:
    return MapLandmark(lid, (n, e, d), w, h, facing, "sign")


def _hover(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Hovering 20 m south of a wall with small wander (wind)."""
    p = np.array([0.3 * np.sin(0.7 * t), 0.4 * np.sin(0.5 * t + 1.0), -5.0 + 0.2 * np.sin(t)])
    return p, (0.03 * np.sin(1.3 * t), 0.03 * np.cos(1.1 * t), 0.05 * np.sin(0.3 * t))


def _survey(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Lawnmower legs at 30 m over a field, 5 m/s, 20 m leg spacing."""
    leg = int(t // 12.0)
    s = (t % 12.0) * 5.0 - 30.0
    north = s if leg % 2 == 0 else -s
    p = np.array([north, -20.0 + 20.0 * (leg % 3), -30.0])
    yaw = 0.0 if leg % 2 == 0 else np.pi
    return p, (0.02 * np.sin(2.0 * t), -0.08, yaw)


def _approach(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Flying north towards a wall sign from 25 m to 6 m away, gently weaving."""
    p = np.array([-25.0 + 1.0 * t, 1.0 * np.sin(0.4 * t), -3.0 + 0.3 * np.sin(0.3 * t)])
    return p, (0.02 * np.sin(t), 0.02 * np.cos(0.8 * t), 0.04 * np.sin(0.4 * t))


def _pair(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Slow crossing 15 m from two wall signs 12 m apart."""
    p = np.array([-15.0 + 0.5 * np.sin(0.2 * t), -2.0 + 0.2 * t, -4.0])
    return p, (0.03 * np.sin(0.9 * t), 0.02 * np.sin(0.7 * t), 0.05 * np.sin(0.25 * t))


def scenarios(make: Callable[..., Scenario] = Scenario) -> list[Scenario]:
    """The four reference scenarios: hover, survey, single + laser, two + attitude."""
    wall = tuple(
        _sign(f"W{i}", 20.0, e, d, 180.0, w, h)
        for i, (e, d, w, h) in enumerate(
            [
                (-7.0, -4.0, 1.2, 1.2),
                (-2.0, -7.0, 1.0, 0.7),
                (3.0, -3.0, 1.2, 1.2),
                (7.0, -6.0, 1.5, 1.0),
            ]
        )
    )
    field_ = tuple(
        _sign(f"G{i}{j}", n, e, 0.0, None, 2.0, 2.0)
        for i, n in enumerate(range(-45, 46, 15))
        for j, e in enumerate(range(-30, 31, 15))
    )
    one = (_sign("S0", 0.0, 0.0, -3.0, 180.0, 1.0, 1.0),)
    two = (
        _sign("P0", 0.0, -8.0, -4.0, 180.0, 1.0, 1.0),
        _sign("P1", 0.0, 4.0, -5.0, 180.0, 1.0, 1.0),
    )
    return [
        make("hover", wall, FORWARD_CAMERA, _hover, 30.0),
        make("survey", field_, DOWN_CAMERA, _survey, 72.0, use_attitude=True),
        make(
            "single_landmark_laser",
            one,
            FORWARD_CAMERA,
            _approach,
            19.0,
            use_corners=False,
            use_attitude=True,
            laser_axis_body=(1.0, 0.0, 0.0),
        ),
        make(
            "two_landmarks_attitude",
            two,
            FORWARD_CAMERA,
            _pair,
            30.0,
            use_corners=False,
            use_attitude=True,
        ),
    ]
