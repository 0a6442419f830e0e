"""The pixel noise of the user's own camera (``companion calibrate noise``).

A landmark is held still in front of the camera (camera on a tripod, or the vehicle on
the ground); the real perception (acquisition, tracking, ECC corner alignment) runs on
every frame and the spread of each corner about its mean is the jitter the pose solver
will see.  The perception gives a plate of width W the corner sigma
``pixel_sigma_px * s * (ref * s / W) ** exponent`` (``CornerNoise.sigma``; s is
the rectification's stretch), so the value written is the jitter divided by that factor:
on this plate, the perception then states exactly the jitter measured.  (In flight the
perception states the larger of that and the alignment's own fit sigma times
``perception.fit_sigma_scale``, ``tracker.verify.fit_corner_sigma``: the fit follows what a
still scene cannot show, e.g. a blurred or badly lit plate; it is not calibrated here.)

What a still scene cannot show: errors that do not change from frame to frame (a corner
drawn in by the alignment, a map's wrong size).  The measured value is a lower bound of
the corner error; docs/deploy.md says how to check it in flight (the fixes' NEES).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from companion.app import Frame
from companion.errors import InputError
from companion.perception import Perception

MIN_FRAMES = 30
#: A floor under the value written (a noise-free input would give 0, which the solver refuses).
MIN_SIGMA_PX = 0.01
#: The landmark's mean corner may not move more than this (pixels) over the recording.
MAX_DRIFT_PX = 2.0


@dataclass(frozen=True)
class NoiseResult:
    """What was measured, and the ``pose.pixel_sigma_px`` that states it."""

    landmark_id: str
    frames_read: int
    frames_used: int
    jitter_px: float  # RMS of a corner coordinate about its mean
    plate_width_px: float
    factor: float  # the perception's corner sigma per 1 px of pixel_sigma_px, this plate
    drift_px: float

    @property
    def pixel_sigma_px(self) -> float:
        """The value to configure."""
        return max(self.jitter_px / self.factor, MIN_SIGMA_PX)


def measure_noise(perception: Perception, frames: Iterable[Frame], landmark_id: str,
                  progress: Callable[[str], None] | None = None) -> NoiseResult:
    """Run the perception on ``frames`` and measure ``landmark_id``'s corner jitter."""
    corners: list[np.ndarray] = []
    factors: list[float] = []
    read = 0
    unit = perception.pose_config.pixel_sigma_px
    for frame in frames:
        read += 1
        perception.process(frame)
        perception.housekeeping(frame)
        track = perception.tracks.get(landmark_id)
        if track is not None and track.corners is not None:
            quad = np.asarray(track.corners, dtype=np.float64).copy()
            corners.append(quad)
            sigma = perception.noise.sigma([(float(u), float(v)) for u, v in quad])
            factors.append((sigma or unit) / unit)
        if progress is not None and read % 30 == 0:
            progress(f"{read} frames, {len(corners)} with {landmark_id}'s corners")
    return summarise(landmark_id, read, corners, factors)


def summarise(landmark_id: str, read: int, corners: list[np.ndarray],
              factors: list[float]) -> NoiseResult:
    """The jitter of the collected corners; one-line errors when it cannot be trusted."""
    if len(corners) < MIN_FRAMES:
        raise InputError(
            f"calibrate noise: landmark {landmark_id} had aligned corners in {len(corners)} "
            f"of {read} frames (need {MIN_FRAMES}): is it in view, lit, and in the map with "
            "an appearance image?")
    stack = np.stack(corners)  # (F, 4, 2)
    centres = stack.mean(axis=1)
    drift = float(np.linalg.norm(centres - centres.mean(axis=0), axis=1).max())
    if drift > MAX_DRIFT_PX:
        raise InputError(f"calibrate noise: landmark {landmark_id} moved {drift:.1f} px "
                         f"(at most {MAX_DRIFT_PX:g}): hold the camera and the landmark still")
    resid = stack - stack.mean(axis=0)
    n = len(stack)
    jitter = math.sqrt(float((resid**2).mean()) * n / (n - 1))
    width = float(np.mean(np.ptp(stack[:, :, 0], axis=1)))
    return NoiseResult(landmark_id, read, n, jitter, width, float(np.median(factors)), drift)


def noise_toml(result: NoiseResult, camera_file: str, when: str) -> str:
    """The ``[pose]`` layer to include in the vehicle's configuration."""
    return (
        f"# Pixel noise measured by companion calibrate noise ({when}) with the camera model "
        f"from\n# {camera_file}: landmark {result.landmark_id} held still, "
        f"{result.frames_used} frames,\n# corner jitter {result.jitter_px:.4f} px on a plate "
        f"{result.plate_width_px:.0f} px wide (perception factor {result.factor:.3f}).\n"
        "# A lower bound: errors constant over the recording are not in it (docs/deploy.md).\n"
        "\n[pose]\n"
        f"pixel_sigma_px = {result.pixel_sigma_px:.4f}\n"
    )
