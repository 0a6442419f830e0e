"""``companion synth``: render a scenario into a recorded stream folder with truth."""

from __future__ import annotations

import argparse
import dataclasses
import logging
from pathlib import Path

from companion.cli import positive_seconds
from companion.core.resources import scenario_dir
from companion.core.stream_io import IMAGE_FORMATS
from companion.errors import ConfigError
from companion.settings import SIM_LAYERS, Settings

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion synth``."""
    names = ", ".join(sorted(p.stem for p in scenario_dir().glob("*.toml")))
    parser = sub.add_parser(
        "synth", help="write a simulated flight as a recorded stream with truth",
        description="Render a scenario of the simulated world (camera frames, landmark boxes "
        "and corners, vehicle and camera poses, range finder) into a recorded stream folder "
        f"(docs/formats.md). Built-in scenarios: {names}.",
    )
    parser.add_argument("--scenario", metavar="NAME|FILE",
                        help="a built-in scenario name or a scenario TOML file")
    parser.add_argument("--world", choices=("real",),
                        help="instead of a scenario: 'real', a real-imagery world (a real aerial "
                        "photograph as ground, landmarks cut from real photographs, drawn from "
                        "--seed; docs/sim.md)")
    parser.add_argument("--ground", type=Path, metavar="PHOTO",
                        help="--world real: the aerial photograph (default: drawn by --seed)")
    parser.add_argument("--crop", action="append", default=[], metavar="IMAGE:X,Y,W,H",
                        help="--world real: one landmark cut from IMAGE (repeat; default: "
                        "textured crops of shared frames drawn by --seed)")
    parser.add_argument("--jpeg-quality", type=int, default=90, metavar="Q",
                        help="JPEG quality for --format jpg (default 90)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="the stream folder to create")
    parser.add_argument("--seconds", type=positive_seconds,
                        metavar="S", help="duration (default: scenario)")
    parser.add_argument("--fps", type=float, metavar="F", help="frame rate (default: scenario)")
    parser.add_argument("--seed", type=int, metavar="N", help="random seed (default: scenario)")
    parser.add_argument("--format", choices=IMAGE_FORMATS,
                        help="png files (lossless, default for a scenario), jpg files (default "
                        "for --world real), or one lossless FFV1 video (ffv1)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace a stream already in --out")
    parser.set_defaults(handler=run, shipped=SIM_LAYERS)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Render and write; print a one-line summary."""
    if not 1 <= args.jpeg_quality <= 100:
        raise ConfigError(f"--jpeg-quality: expected 1-100, got {args.jpeg_quality}")
    if args.world == "real":
        return _run_real(args)
    if args.scenario is None:
        raise ConfigError("synth: give --scenario NAME|FILE or --world real")
    from companion.sim.scenario import load_scenario  # the simulator: only when it renders
    from companion.sim.simulator import Simulator
    from companion.sim.synth import synth_stream

    scenario = load_scenario(args.scenario)
    if args.fps is not None and not 0 < args.fps < float("inf"):
        raise ConfigError(f"--fps: expected a finite number > 0, got {args.fps:g}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")
    scenario = dataclasses.replace(
        scenario,
        seconds=args.seconds or scenario.seconds,
        fps=args.fps or scenario.fps,
        seed=scenario.seed if args.seed is None else args.seed,
    )
    simulator = Simulator(scenario)

    def progress(done: int, total: int) -> None:
        if done % max(1, round(scenario.fps * 5)) == 0:
            log.info("synth: %d/%d frames", done, total)

    count = synth_stream(simulator, args.out, image_format=args.format or "png",
                         jpeg_quality=args.jpeg_quality, overwrite=args.overwrite,
                         progress=progress)
    print(f"{args.out}: {count} frames of scenario '{scenario.name}' "
          f"({scenario.seconds:g} s at {scenario.fps:g} fps, seed {scenario.seed})")
    return 0


def _crop(text: str) -> tuple[Path, tuple[int, int, int, int]]:
    path, _, box = text.rpartition(":")
    try:
        x, y, w, h = (int(v) for v in box.split(","))
    except ValueError:
        raise ConfigError(f"--crop {text}: expected IMAGE:X,Y,W,H (pixels)") from None
    return Path(path), (x, y, w, h)


def _run_real(args: argparse.Namespace) -> int:
    """``--world real``: the real-imagery world of --seed."""
    if args.scenario is not None:
        raise ConfigError("synth: --world real and --scenario exclude each other")
    from companion.sim.realworld import RealWorldSpec, synth_real

    seed = 0 if args.seed is None else args.seed
    crops = tuple(_crop(c) for c in args.crop)
    spec = RealWorldSpec(seed=seed, ground=args.ground, crops=crops,
                         landmarks=len(crops) or RealWorldSpec.landmarks,
                         seconds=args.seconds or RealWorldSpec.seconds,
                         fps=args.fps or RealWorldSpec.fps)
    fmt = args.format or "jpg"
    sim, count = synth_real(spec, args.out, image_format=fmt, jpeg_quality=args.jpeg_quality,
                            overwrite=args.overwrite)
    print(f"{args.out}: {count} frames of the real-imagery world "
          f"'{sim.scenario.name}' ({spec.seconds:g} s at {spec.fps:g} fps, {fmt})")
    return 0
