"""Each tracked corner's error against its stated sigma, on a recorded stream with truth.

Runs the perception over a stream as ``benchmarks/perception_stream.py`` does (same
configuration layers and attitude noise) and, for every track with corners on every frame,
compares the four corners with the truth's (the landmark's map corners projected with
``truth_pose.csv`` and the stream's camera).  Prints, per bin of plate width (px) and for
all: the number of plate sightings, the RMS corner error (px, over the eight coordinates),
the RMS of the stated sigma, and the share of sightings whose normalised error
``sum(err^2) / sigma^2`` lies under the chi-square 95 % point for 8 degrees of freedom
(0.95 when the sigma is honest and the errors Gaussian); then the error along each of the
outline's modes (shift, rotation, scale, aspect, shear, perspective) over the stated sigma,
which shows the errors a plate's corners share.  ``--dump`` prints each sighting.

    PYTHONPATH=. python benchmarks/corner_errors.py STREAM [--frames N] [--set KEY=VALUE]
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import cv2
import numpy as np

from benchmarks.perception_stream import ATT_SIGMA_RAD, frames, load_stream_map
from benchmarks.perception_survey import noisy_attitude
from companion.core.stream_format import read_meta
from companion.core.stream_io import read_truth
from companion.perception import Perception, SideSensors
from companion.settings import SIM_LAYERS, load_settings
from tracker.pose.inputs import outline_basis
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import AttitudeSample

CHI2_8_95 = 15.507  # chi-square 95 % point, 8 degrees of freedom
BINS_PX = (0, 40, 70, 110, 180, 10_000)


def sightings(folder: Path, args: argparse.Namespace) -> list[tuple[float, ...]]:
    """(width px, error RMS px, stated sigma px, size-model sigma px, fit sigma px or nan,
    frame index, mean x error px, mean y error px, then the error along each of the
    outline's eight modes (``tracker.pose.inputs.outline_basis``) over the stated sigma)
    per track with corners per frame."""
    meta = read_meta(folder)
    truth = read_truth(folder)
    landmarks, refs = load_stream_map(folder)
    by_id = {lm.landmark_id: lm for lm in landmarks}
    settings = load_settings(sets=args.set, shipped=() if args.deployment else SIM_LAYERS)
    times: dict[int, AttitudeSample] = {}

    def sensors(t_us: int) -> SideSensors:
        att = times.get(t_us)
        return SideSensors() if att is None else SideSensors(attitude=noisy_attitude(att))

    perception = Perception(meta.camera, landmarks, refs, sensors=sensors,
                            config=settings.perception, tracker_config=settings.tracker,
                            pose_config=settings.pose, acquire_config=settings.acquire,
                            gate_config=settings.fixgate, seed=0)
    cam = perception.camera
    out: list[tuple[float, ...]] = []
    for frame in frames(folder, args.frames):
        ft = truth.get(frame.index)
        if ft is not None:
            p = ft.pose
            times[frame.t_us] = AttitudeSample(frame.t_us, p.roll_rad, p.pitch_rad,
                                               p.yaw_rad, *ATT_SIGMA_RAD)
        perception.process(frame)
        perception.housekeeping(frame)
        if ft is None:
            continue
        p = ft.pose
        pos = np.array([p.north_m, p.east_m, p.down_m])
        used = {o.landmark_id: perception.noise.floor(o, perception.tracks)
                for o in perception.observations(frame.index)}
        for lid, track in perception.tracks.items():
            obs = used.get(lid)
            if track.corners is None or obs is None or obs.corners_px is None:
                continue
            pts = cam.world_to_camera(landmark_corners_ned(by_id[lid]), pos,
                                      (p.roll_rad, p.pitch_rad, p.yaw_rad))
            if not np.all(pts[:, 2] > 0):
                continue
            true = cam.project_camera_points(pts)
            err = np.asarray(obs.corners_px) - true
            quad = np.asarray(obs.corners_px)
            width = float(np.ptp(quad[:, 0]))
            model = perception.noise.sigma(obs.corners_px) or float("nan")
            fit = float("nan") if track.fit_sigma is None else track.fit_sigma
            stated = obs.corner_sigma_px or 0.0
            modes = outline_basis(quad).T @ err.ravel() / max(stated, 1e-9)
            out.append((width, float(np.sqrt(np.mean(err**2))), stated,
                        model, fit, frame.index, *err.mean(axis=0), *modes))
            if args.dump:
                print(f"frame {frame.index} {lid} width {width:.0f} err "
                      f"{out[-1][1]:.3f} stated {out[-1][2]:.3f} model {model:.3f} "
                      f"fit {fit:.3f}")
    perception.close()
    return out


def report(rows: list[tuple[float, ...]]) -> None:
    """The table of the module's notes."""
    a = np.asarray(rows)
    print("width px      n   err RMS px  stated RMS px  model RMS px  fit RMS px  inside 95 %"
          "  mean dx, dy px")
    for lo, hi in [*itertools.pairwise(BINS_PX), (0, 10_000)]:
        sel = a[(a[:, 0] >= lo) & (a[:, 0] < hi)]
        if not len(sel):
            continue
        nees = 8 * sel[:, 1] ** 2 / sel[:, 2] ** 2
        fit = sel[:, 4][np.isfinite(sel[:, 4])]
        fit_rms = float(np.sqrt(np.mean(fit**2))) if len(fit) else float("nan")
        print(f"{lo:>4}-{hi:<5} {len(sel):>6}  {np.sqrt(np.mean(sel[:, 1] ** 2)):10.3f}  "
              f"{np.sqrt(np.mean(sel[:, 2] ** 2)):13.3f}  {np.sqrt(np.mean(sel[:, 3] ** 2)):12.3f}"
              f"  {fit_rms:10.3f}  {np.mean(nees < CHI2_8_95):11.3f}"
              f"  {np.mean(sel[:, 6]):+.3f}, {np.mean(sel[:, 7]):+.3f}")


MODES = ("shift x", "shift y", "rotation", "scale", "aspect", "shear", "persp x", "persp y")


def report_modes(rows: list[tuple[float, ...]]) -> None:
    """Per bin of plate width, the robust spread (1.4826 x the median absolute value) of
    the error along each outline mode over the stated sigma: 1 for every mode when the
    corners' errors are independent, Gaussian and honestly stated."""
    a = np.asarray(rows)
    print("width px      n  " + "  ".join(f"{m:>8}" for m in MODES))
    for lo, hi in [*itertools.pairwise(BINS_PX), (0, 10_000)]:
        sel = a[(a[:, 0] >= lo) & (a[:, 0] < hi)]
        if len(sel):
            spread = 1.4826 * np.median(np.abs(sel[:, 8:16]), axis=0)
            print(f"{lo:>4}-{hi:<5} {len(sel):>6}  " + "  ".join(f"{v:8.3f}" for v in spread))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stream", type=Path)
    parser.add_argument("--frames", type=int, default=None)
    parser.add_argument("--deployment", action="store_true",
                        help="default.toml only (as companion run), not the sim layer")
    parser.add_argument("--dump", action="store_true", help="print every sighting")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a setting, as companion --set does (repeat)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rows = sightings(args.stream, args)
    report(rows)
    report_modes(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
