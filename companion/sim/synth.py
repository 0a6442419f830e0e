"""Write a scenario as a recorded stream folder with truth (``companion synth``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from companion.sources.stream_io import StreamWriter


def synth_stream(
    simulator: Simulator,
    out: Path,
    *,
    image_format: str = "png",
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> int:
    """Render every frame of the scenario (``seconds * fps``) into ``out``; frame count.

    Times are the scenario clock: frame k has ``t_us = round(k * 1e6 / fps)``.
    """
    s = simulator.scenario
    total = max(1, round(s.seconds * s.fps))
    with StreamWriter(out, simulator.stream_meta(), image_format, overwrite=overwrite) as writer:
        for index in range(total):
            image, truth = simulator.render(index)
            frame = Frame(index, round(index * 1e6 / s.fps), image, s.camera_id)
            writer.write(frame, truth)
            if progress is not None:
                progress(index + 1, total)
    return total
