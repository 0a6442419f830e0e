"""A landmark held still in front of the simulated camera, recorded as a stream with a
known corner jitter, and the map and vehicle configuration that fly it (shared by the
calibrate-noise, check and installed-wheel tests)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.core.resources import config_dir
from companion.core.stream_io import StreamWriter
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from tracker.camera import CameraModel

ORIGIN = (47.3769, 8.5417, 408.0)  # config/landmarks.geojson's
HOVER_T_S = 2.0  # hover.toml: wall-02, sign-01 and sign-02 in view


@dataclass(frozen=True)
class StillScene:
    """What a test needs: the stream, the map with appearance images, the camera."""

    stream: Path
    map_path: Path
    camera: CameraModel
    #: RMS of the offsets actually drawn about their mean, per coordinate (px)
    jitter_px: float


#: Gaussian sigma (px) of a signpost's appearance photo too blurred for the matcher.
PLAIN_BLUR_PX = 12.0


def map_with_appearances(folder: Path, sim: Simulator, plain_signs: bool = False) -> Path:
    """config/landmarks.geojson with each landmark's rendered texture as its appearance.

    The simulated signposts are plain plates with 2-6 ORB features, fewer than the
    simulator layer's ORB matcher needs (found by prediction from a fix, never by
    matching): left out unless ``plain_signs``.  The deployment layer's SIFT finds 80-89 on
    them, so with ``plain_signs`` their appearance is written as a photo too blurred to
    match (Gaussian sigma 12 px: 1-5 SIFT features, 8 needed), on which ``companion
    check`` must fail."""
    doc = json.loads((config_dir() / "landmarks.geojson").read_text(encoding="utf-8"))
    if not plain_signs:
        doc["features"] = [f for f in doc["features"]
                           if f["properties"]["category"] != "signpost"]
    folder.mkdir(parents=True, exist_ok=True)
    for feature in doc["features"]:
        texture = sim.world.landmark(feature["id"]).quad.texture
        if plain_signs and feature["properties"]["category"] == "signpost":
            texture = cv2.GaussianBlur(texture, (0, 0), PLAIN_BLUR_PX)
        cv2.imwrite(str(folder / f"{feature['id']}.png"), texture)
        feature["properties"]["appearance"] = f"{feature['id']}.png"
        feature["properties"]["appearance_box"] = [0, 0, texture.shape[1], texture.shape[0]]
    path = folder / "landmarks.geojson"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def still_scene(folder: Path, jitter_px: float, frames: int = 90, seed: int = 0,
                plain_signs: bool = False) -> StillScene:
    """``frames`` of the hover scene at one instant, each shifted by a random sub-pixel
    offset (1-sigma ``jitter_px`` in x and in y: every corner moves with it) and with
    2 grey levels of pixel noise."""
    sim = Simulator(load_scenario("hover"))
    base, _ = sim.render(0, HOVER_T_S)
    rng = np.random.default_rng(seed)
    meta = sim.stream_meta()
    writer = StreamWriter(folder / "stream", meta)
    offsets = rng.normal(0.0, jitter_px, (frames, 2))
    for i, (dx, dy) in enumerate(offsets):
        shift = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]])
        image = cv2.warpAffine(base, shift, (base.shape[1], base.shape[0]),
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        noisy = image.astype(np.float64) + rng.normal(0.0, 2.0, image.shape)
        writer.write(Frame(i, round(i * 1e6 / 30), np.clip(noisy, 0, 255).astype(np.uint8)))
    writer.close()
    drawn = float(np.sqrt(((offsets - offsets.mean(axis=0)) ** 2).mean()))
    return StillScene(folder / "stream", map_with_appearances(folder / "map", sim, plain_signs),
                      sim.scenario.camera, drawn)


def camera_toml(camera: CameraModel) -> str:
    """A camera file for ``camera``."""
    return (f"[camera]\nwidth = {camera.width}\nheight = {camera.height}\n"
            f"fx = {camera.fx}\nfy = {camera.fy}\ncx = {camera.cx}\ncy = {camera.cy}\n"
            f"distortion = {list(camera.distortion)}\n"
            f"mount_rpy_deg = {list(camera.mount_rpy_deg)}\n")


def vehicle_toml(scene: StillScene, camera_file: str, extra: str = "",
                 endpoint: str = "udpout:127.0.0.1:14550") -> str:
    """A vehicle configuration flying the still scene's stream with its map."""
    lat, lon, alt = ORIGIN
    return (f'include = ["{camera_file}"]\n{extra}\n'
            f'[source]\nkind = "stream"\nspec = "{scene.stream}"\n\n'
            f'[landmarks]\nmap_path = "{scene.map_path}"\ndb_path = "landmarks.sqlite"\n\n'
            f'[mavlink]\nendpoint = "{endpoint}"\n'
            f"origin_lat_deg = {lat}\norigin_lon_deg = {lon}\norigin_alt_m = {alt}\n\n"
            "[monitor]\nenabled = false\n")
