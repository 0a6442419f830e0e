"""``companion calibrate camera|noise``: a real camera's intrinsics and its pixel noise.

``camera`` fits intrinsics and distortion to views of a chessboard or ChArUco board and
writes a camera file (``config/cameras/`` format); ``noise`` measures the corner jitter the
perception delivers on that camera for a landmark held still and writes
``pose.pixel_sigma_px`` (docs/deploy.md walks both).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from companion.calibration import (
    BoardSpec,
    CalibrationError,
    Limits,
    calibrate,
    camera_toml,
    collect,
)
from companion.calibration_io import (
    CaptureSession,
    folder_frames,
    refuse_existing,
    write_atomically,
)
from companion.cli import calibrate_noise
from companion.settings import Settings


def _squares(text: str) -> tuple[int, int]:
    cols, sep, rows = text.lower().partition("x")
    if not sep or not cols.isdigit() or not rows.isdigit() or min(int(cols), int(rows)) < 3:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS squares, each >= 3, got {text!r}")
    return int(cols), int(rows)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion calibrate``."""
    parser = sub.add_parser(
        "calibrate", help="measure a real camera: intrinsics and distortion, pixel noise",
        description="camera: intrinsics and distortion from a chessboard or ChArUco board; "
        "noise: the corner jitter of a landmark held still -> pose.pixel_sigma_px.")
    actions = parser.add_subparsers(dest="calibrate_action", metavar="ACTION", required=True)
    cam = actions.add_parser(
        "camera", help="intrinsics and distortion from views of a board -> a camera file",
        description="Find the board in every frame, keep sharp views that add coverage or "
        "variety, fit the camera model, print the RMS reprojection error and the worst "
        "views, and write a camera TOML.  Refuses (nothing written) when no board is found, "
        "too few views are sharp, or the views do not cover the image.")
    src = cam.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", type=Path, metavar="DIR", help="a folder of images")
    src.add_argument("--video", metavar="FILE", help="a video file")
    src.add_argument("--camera", metavar="SPEC",
                     help="a live camera: device index, V4L2 path, GStreamer pipeline or URL")
    cam.add_argument("--out", type=Path, required=True, metavar="FILE.toml")
    cam.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    cam.add_argument("--board", choices=("chessboard", "charuco"), default="chessboard")
    cam.add_argument("--squares", type=_squares, default=(10, 7), metavar="COLSxROWS",
                     help="squares across and down (default 10x7: 9x6 inner corners)")
    cam.add_argument("--square-mm", type=float, default=30.0, help="square side (default 30)")
    cam.add_argument("--marker-mm", type=float, default=22.0, help="ChArUco marker side")
    cam.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco marker dictionary")
    cam.add_argument("--min-views", type=int, default=Limits.min_views)
    cam.add_argument("--max-views", type=int, default=Limits.max_views)
    cam.add_argument("--min-coverage", type=float, default=Limits.min_coverage,
                     help="share of the image's 4x4 cells the corners must reach (0.6)")
    cam.add_argument("--max-blur-px", type=float, default=Limits.max_blur_px,
                     help="refuse views whose edges rise over more pixels (default 4)")
    cam.add_argument("--every-s", type=float, default=0.5,
                     help="video or camera: look at one frame every this many seconds")
    cam.add_argument("--seconds", type=float, default=90.0,
                     help="live camera: stop after this long (default 90), or as soon as "
                     "--max-views views are kept")
    cam.add_argument("--fit-k3", action="store_true",
                     help="also fit k3 (wide-angle lenses); default k3 = 0")
    cam.set_defaults(handler=run)
    calibrate_noise.register_action(actions)


def _session(args: argparse.Namespace) -> CaptureSession | None:
    if args.video is not None:
        return CaptureSession(args.video, args.every_s)
    if args.camera is not None:
        return CaptureSession(args.camera, args.every_s, args.seconds, live=True)
    return None


def run(args: argparse.Namespace, settings: Settings) -> int:
    """``calibrate camera``: collect views, fit, report, write."""
    spec = BoardSpec(args.board, args.squares, args.square_mm / 1000.0,
                     args.marker_mm / 1000.0, args.dictionary)
    limits = Limits(args.min_views, args.min_coverage, args.max_views, args.max_blur_px,
                    args.fit_k3)

    def progress(line: str) -> None:
        print(f"calibrate: {line}", file=sys.stderr, flush=True)

    refuse_existing(args.out, args.overwrite)  # before the session, not after it
    session = _session(args)
    frames = folder_frames(args.images) if session is None else session.frames()
    try:
        picker, size = collect(frames, spec, limits, progress)
    finally:
        frames.close()  # a camera is released before the fit, not when collected
    try:
        result = calibrate(picker, size, spec, limits)
    except CalibrationError as err:
        if session is None or not session.timed_out:
            raise
        raise CalibrationError(f"{err} (the camera stopped at --seconds {args.seconds:g}: "
                               "allow longer)") from None
    c = result.camera
    print(f"calibrated on {len(result.view_rms_px)} views of a {spec.describe()} "
          f"({c.width}x{c.height}, views covering {result.coverage:.0%} of the image)")
    print(f"RMS reprojection error {result.rms_px:.3f} px")
    print(f"fx {c.fx:.2f}  fy {c.fy:.2f}  cx {c.cx:.2f}  cy {c.cy:.2f}  distortion "
          f"[{', '.join(f'{v:.5f}' for v in c.distortion)}]")
    print("worst views: " + ", ".join(f"{name} {rms:.3f} px"
                                      for name, rms in result.view_rms_px[:3]))
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    write_atomically(args.out, camera_toml(result, when), args.overwrite)
    print(f"wrote {args.out}")
    return 0
