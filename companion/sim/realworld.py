"""A real-imagery test world (issue 25): a real aerial photograph as the ground, flat
landmarks cut from other real photographs, the simulator's camera, light and noise.

``companion synth --world real --out DIR`` writes it as a recorded stream with truth (JPEG
frames) and its landmark map with the crops as appearance images.  Everything that makes
one world differ from another is drawn from ``seed``: which photograph is the ground (unless
given), which frames the landmarks are cut from and where, where they lie, how big they are,
how the drone turns.  The project is measured on several such worlds, never tuned to one.

The photographs are read from the shared data folder (``LMC_SHARED_DATA``, default
``../shared/data`` beside the repository); nothing of them is copied into the repository.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pymap3d

from companion.core.frames import ImageU8
from companion.core.landmark import Appearance, Landmark
from companion.core.map_file import write_map
from companion.errors import InputError
from companion.sim.effects import EffectSpec
from companion.sim.scenario import OriginConfig, ScenarioConfig
from companion.sim.simulator import Simulator
from companion.sim.synth import synth_stream
from companion.sim.trajectory import TrajectoryConfig, Waypoint
from companion.sim.world import Quad, WorldConfig
from tracker.camera import CameraModel

ROOT = Path(__file__).resolve().parents[2]


#: The settings the real-imagery worlds are replayed and scored with, over the simulator's
#: layer (docs/benchmarks.md): SIFT acquisition (as in deployment), 6 inliers, and the
#: vagueness gate at 5 % of the distance.
REAL_WORLD_SETS = ("--set", 'acquire.features="sift"', "--set", "acquire.min_inliers=6",
                   "--set", "fixgate.max_sigma_rel=0.05")


def shared_data() -> Path:
    """The shared data folder (``LMC_SHARED_DATA`` or ``../shared/data``)."""
    return Path(os.environ.get("LMC_SHARED_DATA", ROOT.parent / "shared" / "data"))


@dataclass(frozen=True)
class RealWorldSpec:
    """What one real-imagery world is made of (all sizes in metres, angles in degrees).

    ``ground``: the aerial photograph (None: drawn by ``seed`` from ``data/aerial``);
    ``crop_sources``: images the landmarks are cut from (empty: the OTB sequences' frames
    and the aerial photographs not used as ground); ``crops``: explicit
    ``(image, (x, y, w, h))`` per landmark instead of crops chosen by ``seed``.
    """

    seed: int = 0
    data: Path = dataclasses.field(default_factory=shared_data)
    ground: Path | None = None
    crop_sources: tuple[Path, ...] = ()
    crops: tuple[tuple[Path, tuple[int, int, int, int]], ...] = ()
    landmarks: int = 6
    seconds: float = 30.0
    fps: float = 30.0
    height_m: float = 17.0
    camera_pitch_deg: float = -70.0
    ground_length_m: float = 64.0  # the photograph's long side on the ground
    plate_size_m: tuple[float, float] = (1.6, 2.6)  # longest side of a landmark, range
    light_low: float = 0.55  # the ramp's end (at the step)
    light_step_s: float = 12.0
    light_high: float = 1.25  # after the step
    warm_from_s: float = 15.0
    vignette: float = 0.35
    noise_sigma: float = 3.0


def _texture_score(grey: np.ndarray) -> float:
    """Mean gradient magnitude: how much a crop has for features to hold on to."""
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1)
    return float(np.mean(np.hypot(gx, gy)))


def _read(path: Path) -> ImageU8:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"{path}: not a readable image")
    return np.asarray(img, dtype=np.uint8)


def choose_crop(image: ImageU8, rng: np.random.Generator, tries: int = 40
                ) -> tuple[int, int, int, int]:
    """The most textured of ``tries`` random boxes (side 90-200 px, aspect 0.6-1.6)."""
    h, w = image.shape[:2]
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    best, best_score = (0, 0, min(w, 64), min(h, 64)), -1.0
    for _ in range(tries):
        side = int(rng.integers(90, 201))
        aspect = float(rng.uniform(0.6, 1.6))
        bw, bh = min(w, round(side * math.sqrt(aspect))), min(h, round(side / math.sqrt(aspect)))
        x, y = int(rng.integers(0, w - bw + 1)), int(rng.integers(0, h - bh + 1))
        score = _texture_score(grey[y : y + bh, x : x + bw])
        if score > best_score:
            best, best_score = (x, y, bw, bh), score
    return best


def _sources(spec: RealWorldSpec, ground: Path) -> list[Path]:
    if spec.crop_sources:
        return list(spec.crop_sources)
    frames = sorted((spec.data / "otb").glob("*/img/*.jpg"))
    aerial = [p for p in sorted((spec.data / "aerial").glob("*.jpg")) if p != ground]
    return frames + aerial


def _ground_path(spec: RealWorldSpec, rng: np.random.Generator) -> Path:
    if spec.ground is not None:
        return spec.ground
    photos = sorted((spec.data / "aerial").glob("*.jpg"))
    if not photos:
        raise InputError(f"{spec.data / 'aerial'}: no aerial photographs (set LMC_SHARED_DATA)")
    return photos[int(rng.integers(0, len(photos)))]


def landmark_crops(spec: RealWorldSpec, ground: Path, rng: np.random.Generator
                   ) -> list[ImageU8]:
    """One appearance image per landmark: the explicit crops, else seeded textured crops of
    seeded source images (each from a different file)."""
    if spec.crops:
        return [_read(p)[y : y + h, x : x + w].copy() for p, (x, y, w, h) in spec.crops]
    sources = _sources(spec, ground)
    if len(sources) < spec.landmarks:
        raise InputError(f"{spec.data}: {len(sources)} images to cut landmarks from, "
                         f"{spec.landmarks} needed (set LMC_SHARED_DATA)")
    picks = rng.choice(len(sources), size=spec.landmarks, replace=False)
    out = []
    for i in picks:
        img = _read(sources[int(i)])
        x, y, w, h = choose_crop(img, rng)
        out.append(img[y : y + h, x : x + w].copy())
    return out


def landmark_layout(spec: RealWorldSpec, crops: list[ImageU8], rng: np.random.Generator
                    ) -> list[tuple[float, float, float, float]]:
    """(north, east, width, height) per landmark: two staggered rows along the flight line,
    jittered, the longest side drawn from ``plate_size_m``, the crop's aspect kept."""
    out = []
    for k, crop in enumerate(crops):
        side = float(rng.uniform(*spec.plate_size_m))
        h_px, w_px = crop.shape[:2]
        w_m, h_m = (side, side * h_px / w_px) if w_px >= h_px else (side * w_px / h_px, side)
        north = -6.0 + 4.5 * k + float(rng.uniform(-0.8, 0.8))
        east = (3.0 if k % 2 else -3.0) + float(rng.uniform(-1.2, 1.2))
        out.append((north, east, w_m, h_m))
    return out


def landmark_records(spec: RealWorldSpec, crops: list[ImageU8],
                     layout: list[tuple[float, float, float, float]]) -> list[Landmark]:
    """Flat landmarks (facing up, on the ground) with their crops as appearance images."""
    o = spec_origin()
    out = []
    for k, (crop, (n, e, w, h)) in enumerate(zip(crops, layout, strict=True)):
        lat, lon, alt = pymap3d.ned2geodetic(n, e, 0.0, o.lat, o.lon, o.alt_m)
        ok, png = cv2.imencode(".png", crop)
        if not ok:
            raise InputError(f"landmark {k}: crop cannot be encoded")
        ch, cw = crop.shape[:2]
        out.append(Landmark(f"real-{k + 1:02d}", f"Real crop {k + 1}", "other", float(lat),
                            float(lon), float(alt), w, h, None, "approved",
                            appearance=Appearance("image/png", png.tobytes(), (0, 0, cw, ch))))
    return out


def spec_origin() -> OriginConfig:
    """The world's WGS84 origin (the ground plane is at its altitude)."""
    return OriginConfig()


def trajectory(spec: RealWorldSpec, rng: np.random.Generator) -> TrajectoryConfig:
    """North along the landmarks at ``height_m``, turning (seeded yaw) so plates rotate."""
    d = -spec.height_m
    yaws = rng.uniform(-30.0, 30.0, 3)
    east = rng.uniform(-1.5, 1.5, 3)
    cruise = max(1.0, spec.seconds - 6.0)
    wps = (Waypoint((-14.0, float(east[0]), d), yaw_deg=float(yaws[0]), hold_s=2.0),
           Waypoint((-4.0, float(east[1]), d), speed_m_s=20.0 / cruise, yaw_deg=float(yaws[1])),
           Waypoint((6.0, float(east[2]), d), speed_m_s=20.0 / cruise, yaw_deg=float(yaws[2]),
                    hold_s=3600.0))
    return TrajectoryConfig(wps, tilt_deg_per_m_s=2.0, sway_m=0.3, sway_period_s=9.0)


def effects(spec: RealWorldSpec) -> tuple[EffectSpec, ...]:
    """Light ramp to ``light_low``, step to ``light_high`` at ``light_step_s``, warm cast,
    vignetting, sensor noise."""
    step = spec.light_high / spec.light_low  # gains multiply: ramp end x step = light_high
    return (
        EffectSpec("illumination_ramp", 0.0, spec.light_step_s, gain_start=1.0,
                   gain_end=spec.light_low),
        EffectSpec("illumination_step", spec.light_step_s, gain_end=step),
        EffectSpec("colour_cast", spec.warm_from_s, cast_bgr=(0.85, 1.0, 1.12)),
        EffectSpec("vignette", strength=spec.vignette),
        EffectSpec("noise", sigma=spec.noise_sigma),
    )


def ground_quad(photo: ImageU8, length_m: float) -> Quad:
    """The photograph flat on the ground, centred on the origin, its long side north."""
    h, w = photo.shape[:2]
    if h > w:
        photo = np.ascontiguousarray(np.rot90(photo))
        h, w = w, h
    half_n, half_e = length_m / 2.0, length_m * h / w / 2.0
    # TL, TR, BR, BL: texture x along north, y along east (seen from above: not mirrored)
    corners = np.array([[-half_n, -half_e, 0.0], [half_n, -half_e, 0.0],
                        [half_n, half_e, 0.0], [-half_n, half_e, 0.0]])
    return Quad(corners, photo, two_sided=True)


def build(spec: RealWorldSpec, scratch: Path) -> Simulator:
    """The simulator of this world; its landmark map is written into ``scratch``."""
    rng = np.random.default_rng([spec.seed, 25])
    ground = _ground_path(spec, rng)
    crops = landmark_crops(spec, ground, rng)
    layout = landmark_layout(spec, crops, rng)
    scratch.mkdir(parents=True, exist_ok=True)
    map_path = scratch / "real_world.geojson"
    write_map(map_path, landmark_records(spec, crops, layout))
    camera = CameraModel(640, 480, 525.0, 525.0, 319.5, 239.5,
                         mount_rpy_deg=(0.0, spec.camera_pitch_deg, 0.0))
    scenario = ScenarioConfig(
        name=f"real-{ground.stem}-seed{spec.seed}",
        description=f"real-imagery world: ground {ground.name}, seed {spec.seed}",
        landmarks=str(map_path), seconds=spec.seconds, fps=spec.fps, seed=spec.seed,
        camera_id="real0", origin=spec_origin(), camera=camera,
        trajectory=trajectory(spec, rng), world=WorldConfig(ground_texture_px=64),
        effects=effects(spec))
    sim = Simulator(scenario)
    sim.world.ground = ground_quad(_read(ground), spec.ground_length_m)
    return sim


def synth_real(spec: RealWorldSpec, out: Path, *, image_format: str = "jpg",
               jpeg_quality: int = 90, overwrite: bool = False) -> tuple[Simulator, int]:
    """Write the world as a recorded stream (with truth and ``landmarks.geojson``)."""
    with tempfile.TemporaryDirectory(prefix="real-world-") as scratch:
        sim = build(spec, Path(scratch))
        count = synth_stream(sim, out, image_format=image_format, jpeg_quality=jpeg_quality,
                             overwrite=overwrite)
    return sim, count
