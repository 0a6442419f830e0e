"""The strict fake's EKF fed by the perception over a recorded stream: the closed loop, offline.

``sitl_tests/test_fly_strict.py`` flies the square in real time, where the load decides
which frames get a fix.  This runs the same loop on one clock: every frame of a stream
written by ``companion synth`` goes through ``Perception`` (as ``perception_stream.py``
builds it), every fix it passes on is fused by the strict fake's estimator
(``mavlink_bridge.fake_ekf.FakeEstimator``, ArduPilot's defaults but no delay: the fix
comes with its frame), and the side sensors are the autopilot's: its attitude is the
truth off by ``--attitude-offset-deg`` (stated 2.5 / 5 deg), its height prior is **the
estimator's own down** (LOCAL_POSITION_NED), its position guess the estimator's position.
The estimator's height comes from ``--height``: ``baro`` (the default, as the strict fake
with the profile's ``EK3_SRC1_POSZ`` 1: a simulated barometer, set before the first fix),
``extnav`` (``EK3_SRC1_POSZ`` 6: the fixes' down) or ``fixes`` (the old fake: 0 until the
first fix, then the fixes' down).  The estimator is propagated with the truth's
acceleration (second differences of the stream's truth) plus its IMU bias and noise.

Prints the estimate's error against the truth (median, max, and where the max is), the
longest time between fused fixes, and per second the worst estimate error (``--per-second``)::

    PYTHONPATH=. python benchmarks/square_loop.py /tmp/sq [--attitude-offset-deg 1 -1 3]
        [--seed 0] [--per-second] [--height baro|extnav|fixes] [--attitude-lag-frames 1]
        [--set fixgate.echo_correlation_s=0] [--every 3]

``--every N`` perceives one frame in N (the estimator still predicts on every frame): the
real-time flight on a loaded machine perceives one frame in two to four, and the plates
then move 3-4 times as far between two looks (docs/decisions.md, "A tracker seated on the
part of a plate in view").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from benchmarks.perception_stream import frames, load_stream_map
from companion.core.stream_format import TruthPose, read_meta
from companion.core.stream_io import read_truth
from companion.perception import Perception, SideSensors
from companion.settings import SIM_LAYERS, load_settings
from mavlink_bridge.fake_ekf import EstimatorConfig, FakeEstimator
from tracker.pose.types import AltitudeSample, AttitudeSample, PoseFix


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stream", type=Path)
    parser.add_argument("--attitude-offset-deg", type=float, nargs=3, default=(1.0, -1.0, 3.0))
    parser.add_argument("--attitude-sigma-deg", type=float, nargs=2, default=(2.5, 5.0))
    parser.add_argument("--altitude-sigma-m", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=0, help="the estimator's IMU seed")
    parser.add_argument("--per-second", action="store_true")
    parser.add_argument("--height", choices=("baro", "extnav", "fixes"), default="baro")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--attitude-lag-frames", type=int, default=0,
                        help="the attitude of this many frames earlier (a capture time "
                        "mapped late onto the autopilot's clock)")
    parser.add_argument("--every", type=int, default=1,
                        help="perceive one frame in this many (a companion that keeps up "
                        "with a third of the camera's frames, as under load in real time)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    folder = args.stream
    meta, truth = read_meta(folder), read_truth(folder)
    landmarks, refs = load_stream_map(folder)
    settings = load_settings(sets=args.set, shipped=SIM_LAYERS)
    # the fix comes with its frame: no delay, no half filter step (one clock, no latency)
    ekf = FakeEstimator(EstimatorConfig(delay_ms=0.0, half_step_ms=0.0,
                                        height_source=args.height), seed=args.seed)
    poses = {i: ft.pose for i, ft in truth.items() if ft.pose is not None}
    off = np.deg2rad(args.attitude_offset_deg)
    sig = np.deg2rad(args.attitude_sigma_deg)
    now: dict[str, int] = {}

    def sensors(t_us: int) -> SideSensors:
        p = poses.get(max(now["index"] - args.attitude_lag_frames, 0))
        if p is None:
            return SideSensors()
        att = AttitudeSample(t_us, p.roll_rad + off[0], p.pitch_rad + off[1],
                             p.yaw_rad + off[2], float(sig[0]), float(sig[1]))
        est = ekf.position()
        return SideSensors(attitude=att, position_ned_m=est if ekf.initialised else None,
                           altitude=AltitudeSample(t_us, est[2], args.altitude_sigma_m))

    perception = Perception(meta.camera, landmarks, refs, sensors=sensors,
                            config=settings.perception, tracker_config=settings.tracker,
                            pose_config=settings.pose, acquire_config=settings.acquire,
                            gate_config=settings.fixgate, seed=args.seed)
    fps = meta.fps
    errors: list[tuple[float, float, float]] = []  # (t, error, its down part)
    fused: list[float] = []
    for frame in frames(folder, None):
        now["index"] = frame.index
        p = poses.get(frame.index)
        if p is None:
            continue
        t = frame.t_us / 1e6
        ekf.predict(t, truth_accel(poses, frame.index, fps))
        ekf.observe_baro(t, p.down_m)
        if frame.index % args.every == 0:
            fix = perception.process(frame).fix
            perception.housekeeping(frame)
        else:
            fix = None
        if isinstance(fix, PoseFix):
            var = np.diag(np.asarray(fix.autopilot_covariance))[:3]  # as the bridge sends
            if ekf.fuse(t, fix.position_ned_m, (var[0], var[1], var[2])).accepted:
                fused.append(t)
        if ekf.initialised:
            d = np.subtract(ekf.position(), (p.north_m, p.east_m, p.down_m))
            errors.append((t, float(np.linalg.norm(d)), abs(float(d[2]))))
    perception.close()
    report(errors, fused, args.per_second)
    return 0


def truth_accel(poses: dict[int, TruthPose], i: int, fps: float) -> np.ndarray:
    """The truth's acceleration at frame ``i`` (second difference; 0 at the ends)."""
    if i - 1 not in poses or i + 1 not in poses:
        return np.zeros(3)
    pos = [np.array([q.north_m, q.east_m, q.down_m])
           for q in (poses[i - 1], poses[i], poses[i + 1])]
    return (pos[0] - 2 * pos[1] + pos[2]) * fps * fps


def report(errors: list[tuple[float, float, float]], fused: list[float],
           per_second: bool) -> None:
    e = np.array([v for _, v, _ in errors])
    down = np.array([v for _, _, v in errors])
    worst = int(np.argmax(e))
    gaps = np.diff(fused) if len(fused) > 1 else np.array([0.0])
    g = int(np.argmax(gaps))
    print(f"estimate error median {np.median(e):.3f} m, max {e[worst]:.3f} m at "
          f"{errors[worst][0]:.1f} s; fused {len(fused)}, longest gap {gaps[g]:.2f} s from "
          f"{fused[g]:.1f} s; down error median {np.median(down):.3f} m, max {down.max():.3f} m")
    if per_second:
        by: dict[int, float] = {}
        for t, v, _ in errors:
            by[int(t)] = max(by.get(int(t), 0.0), v)
        print(" ".join(f"{s}:{v:.2f}" for s, v in sorted(by.items())))


if __name__ == "__main__":
    sys.exit(main())
