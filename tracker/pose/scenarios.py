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
from tracker.pose.types import MapLandmark, NoFix, Observation, PoseFix, PosePrior

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
    #: share of detections given a wrong landmark id (misassociation outliers)
    misname_rate: float = 0.0
    #: detections carry only a category: association from the last fix names them
    unlabelled: bool = False


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
    predicted_rms_m: float  # sqrt(mean trace P_pos): what the covariances promised
    solvers: dict[str, int]
    no_fix_reasons: dict[str, int]
    dropped: int = 0  # landmarks dropped as outliers, summed over the frames

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


def solve_frame(
    scenario: Scenario, frame: SimFrame, config: PoseConfig, prior: PosePrior | None = None
) -> PoseFix | NoFix:
    """Solve one simulated frame with the inputs the scenario grants the solver."""
    obs = frame.observations
    if not scenario.use_corners:
        obs = tuple(replace(o, corners_px=None) for o in obs)
    if scenario.unlabelled:
        obs = tuple(replace(o, landmark_id=None) for o in obs)
    return solve_pose(
        obs,
        scenario.landmarks,
        scenario.camera,
        frame.time_us,
        attitude=frame.attitude if scenario.use_attitude else None,
        altitude=frame.altitude if scenario.use_altitude else None,
        laser=frame.laser,
        prior=prior,
        config=config,
    )


def next_prior(fix: PoseFix | NoFix, last: PosePrior, motion_sigma_m: float) -> PosePrior:
    """The predicted pose for the next frame: the last fix, loosened by the motion allowance.

    Without a fix the previous prediction is kept and loosened further.
    """
    if not isinstance(fix, PoseFix):
        return replace(last, position_sigma_m=last.position_sigma_m + motion_sigma_m)
    sigma = float(np.sqrt(np.max(np.diag(fix.covariance)[:3])))
    att_sigma = float(np.sqrt(np.max(np.diag(fix.covariance)[3:])))
    return PosePrior(
        fix.position_ned_m,
        fix.attitude_rpy_rad,
        sigma + motion_sigma_m,
        att_sigma + float(np.deg2rad(2.0)),
    )


def fly(scenario: Scenario, rng: np.random.Generator) -> list[SimFrame]:
    """Every simulated frame of ``scenario`` (with misnamed detections if it asks)."""
    n_frames = int(scenario.duration_s * scenario.rate_hz)
    frames = []
    for i in range(n_frames):
        frame = simulate_frame(
            scenario.landmarks,
            scenario.camera,
            scenario.trajectory,
            i / scenario.rate_hz,
            rng,
            scenario.noise,
            scenario.laser_axis_body,
        )
        if scenario.misname_rate > 0:
            frame = replace(frame, observations=_misname(frame, scenario, rng))
        frames.append(frame)
    return frames


def _misname(
    frame: SimFrame, scenario: Scenario, rng: np.random.Generator
) -> tuple[Observation, ...]:
    """Give each detection, with probability ``misname_rate``, another landmark's id."""
    ids = [lm.landmark_id for lm in scenario.landmarks]
    out = []
    for o in frame.observations:
        if rng.random() < scenario.misname_rate:
            o = replace(o, landmark_id=str(rng.choice([i for i in ids if i != o.landmark_id])))
        out.append(o)
    return tuple(out)


def run_scenario(
    scenario: Scenario, rng: np.random.Generator, config: PoseConfig | None = None
) -> ScenarioResult:
    """Fly ``scenario`` and score every fix against the truth."""
    cfg = solver_config(scenario, config)
    frames = fly(scenario, rng)
    errs, dists, nees, multi, solvers, reasons = [], [], [], [], Counter[str](), Counter[str]()
    traces: list[float] = []
    dropped = 0
    p0, rpy0 = scenario.trajectory(0.0)  # the first prediction: truth known to ~1 m
    start = p0 + rng.normal(0.0, 1.0, 3)
    prior = PosePrior((float(start[0]), float(start[1]), float(start[2])), rpy0, 1.5, 0.05)
    for frame in frames:
        if scenario.use_attitude:  # predict with the autopilot's current attitude
            a = frame.attitude
            prior = replace(
                prior,
                attitude_rpy_rad=(a.roll_rad, a.pitch_rad, a.yaw_rad),
                attitude_sigma_rad=max(a.roll_pitch_sigma_rad, a.yaw_sigma_rad),
            )
        fix = solve_frame(scenario, frame, cfg, prior if scenario.unlabelled else None)
        prior = next_prior(fix, prior, motion_sigma_m=0.5)
        dropped += sum(n.startswith("dropped") for n in fix.notes)
        if not isinstance(fix, PoseFix):
            reasons[fix.reason.split(":")[0]] += 1
            continue
        solvers[fix.solver] += 1
        e = np.asarray(fix.position_ned_m) - frame.true_position_ned_m
        errs.append(e)
        nees.append(float(e @ np.linalg.solve(fix.covariance[:3, :3], e)))
        traces.append(float(np.trace(fix.covariance[:3, :3])))
        dists.append(_mean_distance(scenario.landmarks, fix, frame.true_position_ned_m))
        multi.append(len(fix.landmark_ids) >= 2)
    result = _summarise(scenario.name, len(frames), errs, dists, nees, multi, solvers, reasons)
    predicted = float(np.sqrt(np.mean(traces))) if traces else float("nan")
    return replace(result, predicted_rms_m=predicted, dropped=dropped)


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
        predicted_rms_m=float("nan"),
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
    """Lawnmower at 30 m and 5 m/s: three 60 m legs north/south, 20 m apart, joined by
    half-circle turns of 10 m radius; yaw follows the track, slight nose-down pitch."""
    v, leg_s, radius = 5.0, 12.0, 10.0
    turn_s = np.pi * radius / v
    period = leg_s + turn_s
    k = min(int(t // period), 2)
    tau = t - k * period
    east0 = -20.0 + 20.0 * k
    sign = 1.0 if k % 2 == 0 else -1.0  # leg 0 and 2 fly north, leg 1 south
    if tau <= leg_s or k == 2:
        north = sign * (-30.0 + v * tau)
        yaw = 0.0 if sign > 0 else np.pi
        p = np.array([north, east0, -30.0])
    else:  # turn about (sign * 30, east0 + 10)
        a = (tau - leg_s) / turn_s * np.pi
        p = np.array(
            [sign * (30.0 + radius * np.sin(a)), east0 + radius - radius * np.cos(a), -30.0]
        )
        yaw = a if sign > 0 else np.pi - a  # heading turns towards east either way
    return p, (0.02 * np.sin(2.0 * t), -0.08, float((yaw + np.pi) % (2 * np.pi) - np.pi))


def _approach(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Flying north towards a wall image from 25 m to 6 m away, gently weaving."""
    p = np.array([-25.0 + 1.0 * t, 0.3 * np.sin(0.4 * t), -3.0 + 0.2 * np.sin(0.3 * t)])
    return p, (0.02 * np.sin(t), 0.02 * np.cos(0.8 * t), 0.015 * np.sin(0.4 * t))


def _pair(t: float) -> tuple[FloatArray, tuple[float, float, float]]:
    """Slow crossing 15 m from two wall signs 10 m apart."""
    p = np.array([-15.0 + 0.5 * np.sin(0.2 * t), -1.5 + 0.1 * t, -4.0])
    return p, (0.03 * np.sin(0.9 * t), 0.02 * np.sin(0.7 * t), 0.05 * np.sin(0.25 * t))


def _wall_signs() -> tuple[MapLandmark, ...]:
    """Four signs on one flat wall 20 m north, facing south (seen head-on)."""
    return tuple(
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


def _street_signs() -> tuple[MapLandmark, ...]:
    """Shop signs on both sides of a 12 m street at 12-28 m, and a facade logo ahead."""
    left = [(12.0, -6.0), (20.0, -6.0), (28.0, -6.0)]  # west side, facing east
    right = [(15.0, 6.0), (24.0, 6.0)]  # east side, facing west
    out = [_sign(f"L{i}", n, e, -4.0 - i, 90.0, 1.5, 1.0) for i, (n, e) in enumerate(left)]
    out += [_sign(f"R{i}", n, e, -3.0 - 2 * i, 270.0, 1.5, 1.0) for i, (n, e) in enumerate(right)]
    out.append(_sign("F0", 35.0, 0.0, -8.0, 180.0, 2.0, 2.0))
    return tuple(out)


def scenarios(make: Callable[..., Scenario] = Scenario) -> list[Scenario]:
    """The reference scenarios (see docs/pose.md)."""
    field_ = tuple(
        _sign(f"G{i}{j}", n, e, 0.0, None, 2.0, 2.0)
        for i, n in enumerate(range(-45, 46, 15))
        for j, e in enumerate(range(-30, 31, 15))
    )
    one = (_sign("S0", 0.0, 0.0, -3.0, 180.0, 2.0, 1.5),)
    two = (
        _sign("P0", 0.0, -5.0, -4.0, 180.0, 1.0, 1.0),
        _sign("P1", 0.0, 5.0, -5.0, 180.0, 1.0, 1.0),
    )
    fwd = FORWARD_CAMERA
    return [
        make("hover_wall", _wall_signs(), fwd, _hover, 30.0),
        make("hover_wall_attitude", _wall_signs(), fwd, _hover, 30.0, use_attitude=True),
        make("hover_street", _street_signs(), fwd, _hover, 30.0),
        make("survey", field_, DOWN_CAMERA, _survey, 48.0, use_attitude=True),
        make(
            "single_landmark_laser",
            one,
            fwd,
            _approach,
            19.0,
            use_corners=False,
            use_attitude=True,
            laser_axis_body=(1.0, 0.0, 0.0),
        ),
        make("two_landmarks_attitude", two, fwd, _pair, 30.0, use_corners=False, use_attitude=True),
        make("two_landmarks_attitude_corners", two, fwd, _pair, 30.0, use_attitude=True),
        make("hover_street_unlabelled", _street_signs(), fwd, _hover, 30.0, unlabelled=True),
        make(
            "survey_unlabelled",
            field_,
            DOWN_CAMERA,
            _survey,
            48.0,
            use_attitude=True,
            unlabelled=True,
        ),
        make("hover_street_misnamed", _street_signs(), fwd, _hover, 30.0, misname_rate=0.1),
        make(
            "survey_misnamed",
            field_,
            DOWN_CAMERA,
            _survey,
            48.0,
            use_attitude=True,
            misname_rate=0.1,
        ),
    ]


def reference_flights() -> list[Scenario]:
    """:func:`scenarios` and, last, the two-landmark pair by box centres with a 0.25 deg yaw
    prior (``two_landmarks_attitude_yaw0.25``): the flights the benchmarks report."""
    runs = scenarios()
    pair = next(s for s in runs if s.name == "two_landmarks_attitude")
    yaw = replace(pair.noise, yaw_sigma_rad=float(np.deg2rad(0.25)))
    return [*runs, replace(pair, name="two_landmarks_attitude_yaw0.25", noise=yaw)]
