"""Write a scenario as a recorded stream folder with truth (``companion synth``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import cv2

from companion.core.frames import Frame
from companion.core.landmark import Appearance
from companion.core.map_file import read_map, write_map
from companion.core.stream_io import StreamWriter
from companion.sim.scenario import landmarks_path
from companion.sim.simulator import Simulator


def synth_stream(
    simulator: Simulator,
    out: Path,
    *,
    image_format: str = "png",
    jpeg_quality: int = 95,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> int:
    """Render every frame of the scenario (``seconds * fps``) into ``out``; frame count.

    Times are the scenario clock: frame k has ``t_us = round(k * 1e6 / fps)``.  Beside the
    frames goes ``landmarks.geojson``: the world's landmark map with the very textures
    the frames show as appearance images (:data:`MAP_NAME`), so that ``companion
    landmarks import`` and ``companion run`` can use the recording like a real one.
    """
    s = simulator.scenario
    total = max(1, round(s.seconds * s.fps))
    with StreamWriter(out, simulator.stream_meta(), image_format, jpeg_quality,
                      overwrite=overwrite) as writer:
        for index in range(total):
            image, truth = simulator.render(index)
            frame = Frame(index, round(index * 1e6 / s.fps), image, s.camera_id)
            writer.write(frame, truth)
            if progress is not None:
                progress(index + 1, total)
    write_world_map(simulator, out)
    return total


#: The landmark map written beside a synthesised stream's frames.
MAP_NAME = "landmarks.geojson"


def write_world_map(simulator: Simulator, out: Path) -> int:
    """``out/landmarks.geojson``: the scenario's map, each landmark with the texture the
    simulator renders as its appearance image (PNG, the whole image is the face)."""
    textures = {lm.landmark_id: lm.quad.texture for lm in simulator.world.landmarks
                if lm.quad.texture is not None}
    records = []
    for lm in read_map(landmarks_path(simulator.scenario)):
        texture = textures.get(lm.id)
        if texture is not None:
            ok, png = cv2.imencode(".png", texture)
            if ok:
                h, w = texture.shape[:2]
                lm = dataclasses.replace(lm, appearance=Appearance("image/png", png.tobytes(),
                                                                   (0, 0, w, h)))
        records.append(lm)
    return write_map(Path(out) / MAP_NAME, records)
