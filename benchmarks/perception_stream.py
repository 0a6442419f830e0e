"""Perception over a recorded stream with truth (issue 25's figures), offline, one clock.

Reads a stream folder written by ``companion synth`` (``--world real`` or ``--scenario``):
frames, ``truth_pose.csv``/``truth_boxes.csv`` and ``landmarks.geojson`` with appearance
images.  Runs ``companion.perception.Perception`` built from the configuration layers as
``companion demo`` builds it (``--deployment``: default.toml alone, as ``companion run``)
on every frame, with the attitude an autopilot would give it: the truth plus Gaussian noise
of its stated sigmas (``perception_survey.noisy_attitude``).  Prints, per run:

* ``fix_share_2plus_visible``: frames with >= 2 landmarks fully in view (truth) that got
  a fix, over those frames;
* RMSE of the fixes (m, and % of the mean distance to the landmarks used), the share with
  NEES inside the 95 % chi-square bounds (``perception_survey.Fixes``);
* ``longest_wrong_track_frames``: the longest run of frames a track sat on a wrong place
  (box IoU with its landmark's truth box < ``--wrong-iou``, or its landmark not in view);
* ``first_fix_after_step_s``: time from ``--light-step-s`` to the next fix;
* ``no_fix_2plus_visible``: why the frames with >= 2 landmarks fully in view got no fix
  (the perception's no-fix reason up to its first colon, counted).

    PYTHONPATH=. python benchmarks/perception_stream.py STREAM [--runs 3] [--deployment]
        [--attitude-offset-deg R P Y [--attitude-sigma-deg RP YAW]]
        [--altitude-sigma-m S [--altitude-offset-m D]] [--light-step-s 12]
        [--frames N] [--json] [--dump] [--set KEY=VALUE ...]

Real-imagery worlds are measured with ``--set 'acquire.features="sift"' --set
acquire.min_inliers=6 --set fixgate.max_sigma_rel=0.05`` (the sim layer keeps ORB and the
vagueness gate off for the renderer's plates).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from benchmarks.perception_survey import NEES_HIGH, NEES_LOW, noisy_attitude
from companion.core.images import read_image
from companion.core.map_file import read_map
from companion.core.stream_format import FrameTruth, read_meta
from companion.core.stream_io import read_truth
from companion.flightmap import placed
from companion.landmarks.geodesy import LocalFrame
from companion.perception import Perception, SideSensors
from companion.settings import SIM_LAYERS, load_settings
from companion.sources.base import Frame
from companion.sources.files import Entry, lossy
from tracker.boxes import box_iou
from tracker.pose.types import AltitudeSample, AttitudeSample, MapLandmark, PoseFix

ATT_SIGMA_RAD = (float(np.deg2rad(0.2)), float(np.deg2rad(1.0)))  # the fake autopilot's


@dataclasses.dataclass
class Score:
    """Per-run accumulators."""

    frames: int = 0
    frames_2plus: int = 0
    fixes_2plus: int = 0
    err: list[float] = dataclasses.field(default_factory=list)
    dist: list[float] = dataclasses.field(default_factory=list)
    nees: list[float] = dataclasses.field(default_factory=list)
    wrong_run: dict[str, int] = dataclasses.field(default_factory=dict)
    longest_wrong: int = 0
    first_fix_after_step_s: float | None = None
    no_fix_2plus: dict[str, int] = dataclasses.field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        err, dist, nees = np.array(self.err), np.array(self.dist), np.array(self.nees)
        rmse = float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")
        d = float(dist.mean()) if len(dist) else float("nan")
        inside = float(np.mean((nees > NEES_LOW) & (nees < NEES_HIGH))) if len(nees) else 0.0
        return {
            "frames": self.frames, "fixes": len(err),
            "frames_2plus_visible": self.frames_2plus,
            "fix_share_2plus_visible": round(self.fixes_2plus / max(self.frames_2plus, 1), 3),
            "rmse_m": round(rmse, 4), "rmse_pct_distance": round(100 * rmse / d, 3),
            "nees_inside_95_share": round(inside, 3),
            # outside the bounds: too cautious (under) or overconfident (over)
            "nees_under_95_share": round(float(np.mean(nees <= NEES_LOW)), 3) if len(nees) else 0.0,
            "nees_over_95_share": round(float(np.mean(nees >= NEES_HIGH)), 3) if len(nees) else 0.0,
            "longest_wrong_track_frames": self.longest_wrong,
            "first_fix_after_step_s": self.first_fix_after_step_s,
            "no_fix_2plus_visible": dict(sorted(self.no_fix_2plus.items(),
                                                key=lambda kv: -kv[1])),
        }


def load_stream_map(folder: Path) -> tuple[list[MapLandmark], dict[str, np.ndarray]]:
    """The stream's landmark map in NED about its origin, and the appearance references."""
    origin = read_meta(folder).origin
    frame = LocalFrame(origin.lat, origin.lon, origin.alt_m)
    landmarks, refs, _ = placed(frame, read_map(folder / "landmarks.geojson"))
    return landmarks, refs


def frames(folder: Path, limit: int | None) -> Iterator[Frame]:
    """The stream's frames in order (recorded times)."""
    import csv

    with (folder / "frames.csv").open(encoding="utf-8") as fh:
        rows = list(csv.reader(fh))[1:]
    for row in rows[:limit]:
        entry = Entry(int(row[0]), int(row[1]), folder / row[2])
        yield Frame(entry.index, entry.t_us, read_image(entry.path), lossy=lossy(entry))


def score_track(score: Score, lid: str, box: tuple[float, float, float, float] | None,
                truth: FrameTruth | None, wrong_iou: float) -> None:
    """Count a track's run on a wrong place (None box: no track, run ends)."""
    if box is None:
        score.wrong_run.pop(lid, None)
        return
    tb = {b.landmark_id: b for b in (truth.boxes if truth else ())}.get(lid)
    on = tb is not None and box_iou(box, (tb.x, tb.y, tb.w, tb.h)) >= wrong_iou
    run = 0 if on else score.wrong_run.get(lid, 0) + 1
    score.wrong_run[lid] = run
    score.longest_wrong = max(score.longest_wrong, run)


def echo_text(fix: PoseFix) -> str:
    """The share of the fix's position sigma that the autopilot's attitude and height
    carry (``PoseFix.echo_covariance``), for ``--dump``."""
    if fix.echo_covariance is None:
        return ""
    echo = float(np.sqrt(np.trace(np.asarray(fix.echo_covariance)[:3, :3])))
    return f" autopilot's part {echo:.3f} m"


def run_once(folder: Path, args: argparse.Namespace, seed: int) -> dict[str, Any]:
    """One pass of the perception over the stream; its summary."""
    meta = read_meta(folder)
    truth = read_truth(folder)
    landmarks, refs = load_stream_map(folder)
    by_id = {lm.landmark_id: lm for lm in landmarks}
    settings = load_settings(sets=args.set, shipped=() if args.deployment else SIM_LAYERS)

    def sensors(t_us: int) -> SideSensors:
        ft = truth_by_time.get(t_us)
        if ft is None:
            return SideSensors()
        p = ft.pose
        alt = None if args.altitude_sigma_m is None else AltitudeSample(
            t_us, p.down_m + args.altitude_offset_m, args.altitude_sigma_m)
        if args.attitude_offset_deg is not None:  # an EKF's slow error, stated honestly
            off = np.deg2rad(args.attitude_offset_deg)
            return SideSensors(attitude=AttitudeSample(
                t_us, p.roll_rad + off[0], p.pitch_rad + off[1], p.yaw_rad + off[2],
                *np.deg2rad(args.attitude_sigma_deg)), altitude=alt)
        att = AttitudeSample(t_us, p.roll_rad, p.pitch_rad, p.yaw_rad, *ATT_SIGMA_RAD)
        if args.exact_attitude:
            return SideSensors(attitude=att, altitude=alt)
        # another draw per run (the noise is seeded by the sample's time), at the frame's time
        drawn = noisy_attitude(dataclasses.replace(att, time_us=t_us + 1_000_003 * seed))
        return SideSensors(attitude=dataclasses.replace(drawn, time_us=t_us), altitude=alt)

    perception = Perception(meta.camera, landmarks, refs, sensors=sensors,
                            config=settings.perception, tracker_config=settings.tracker,
                            pose_config=settings.pose, acquire_config=settings.acquire,
                            gate_config=settings.fixgate, seed=seed)
    truth_by_time: dict[int, FrameTruth] = {}
    score = Score()
    for frame in frames(folder, args.frames):
        ft = truth.get(frame.index)
        if ft is not None:
            truth_by_time[frame.t_us] = ft
        result = perception.process(frame)
        perception.housekeeping(frame)
        score.frames += 1
        full = [b for b in (ft.boxes if ft else ()) if b.in_view_frac >= 1.0
                and b.occluded_frac <= 0.0]
        fix = result.fix if isinstance(result.fix, PoseFix) else None
        if len(full) >= 2:
            score.frames_2plus += 1
            score.fixes_2plus += fix is not None
            if fix is None:
                why = (result.no_fix_reason or "?").split(":")[0][:60]
                score.no_fix_2plus[why] = score.no_fix_2plus.get(why, 0) + 1
        for lid in by_id:
            t = perception.tracks.get(lid)
            score_track(score, lid, None if t is None else t.box, ft, args.wrong_iou)
        t_s = frame.t_us / 1e6
        if (fix is not None and args.light_step_s is not None and t_s >= args.light_step_s
                and score.first_fix_after_step_s is None):
            score.first_fix_after_step_s = round(t_s - args.light_step_s, 3)
        if fix is None or ft is None:
            continue
        p = ft.pose
        true = np.array([p.north_m, p.east_m, p.down_m])
        err = np.asarray(fix.position_ned_m) - true
        score.err.append(float(np.linalg.norm(err)))
        score.dist.append(float(np.mean([np.linalg.norm(true - by_id[i].position_ned_m)
                                         for i in fix.landmark_ids])))
        cov = np.asarray(fix.covariance)[:3, :3]
        score.nees.append(float(err @ np.linalg.solve(cov, err)))
        if args.dump:
            print(f"frame {frame.index} fix {','.join(fix.landmark_ids)} {fix.solver} error "
                  f"{score.err[-1]:.3f} m ({', '.join(f'{v:+.2f}' for v in err)}) sigma "
                  f"{np.sqrt(np.trace(cov)):.3f} m "
                  f"({', '.join(f'{v:.2f}' for v in np.sqrt(np.diag(cov)))}) NEES "
                  f"{score.nees[-1]:.1f}{echo_text(fix)}")
    perception.close()
    return score.summary()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stream", type=Path)
    parser.add_argument("--runs", type=int, default=3, help="runs (seeds 0..runs-1)")
    parser.add_argument("--frames", type=int, default=None)
    parser.add_argument("--deployment", action="store_true",
                        help="default.toml only (as companion run), not the sim layer")
    parser.add_argument("--exact-attitude", action="store_true")
    parser.add_argument("--attitude-offset-deg", type=float, nargs=3, default=None,
                        metavar=("ROLL", "PITCH", "YAW"),
                        help="the attitude off truth by these constant angles (the strict "
                        "fake autopilot's EKF: about 1, -1, 3), stated as --attitude-sigma-deg")
    parser.add_argument("--attitude-sigma-deg", type=float, nargs=2, default=(2.5, 5.0),
                        metavar=("ROLL_PITCH", "YAW"),
                        help="stated 1-sigma with --attitude-offset-deg (default 2.5 5: "
                        "pose.attitude_*_sigma_deg's defaults)")
    parser.add_argument("--altitude-sigma-m", type=float, default=None,
                        help="give the height prior (LOCAL_POSITION_NED's down in a flight): "
                        "the truth plus --altitude-offset-m, stated with this 1-sigma "
                        "(pose.altitude_sigma_m is 0.5); default: no height")
    parser.add_argument("--altitude-offset-m", type=float, default=0.0,
                        help="the height prior's constant error (m, down)")
    parser.add_argument("--light-step-s", type=float, default=None)
    parser.add_argument("--wrong-iou", type=float, default=0.2,
                        help="a track whose box overlaps its landmark's truth box less is "
                        "on a wrong place")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--dump", action="store_true", help="print every fix")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a setting, as companion --set does (repeat)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    results = [run_once(args.stream, args, seed) for seed in range(args.runs)]
    for n, r in enumerate(results):
        print(json.dumps(r) if args.json else f"run {n}: " + ", ".join(
            f"{k} {v}" for k, v in r.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
