"""Input checks of the pose solver: bad observations and stale or broken side samples."""

from __future__ import annotations

import math

from tracker.pose.config import PoseConfig
from tracker.pose.types import AltitudeSample, AttitudeSample, Observation, RangeSample


def _finite(values: tuple[float, ...]) -> bool:
    """All real numbers and finite (False for non-numbers too)."""
    try:
        return all(map(math.isfinite, values))
    except TypeError:
        return False


def check_observation(obs: Observation, width_px: int, height_px: int) -> str:
    """Empty when ``obs`` is usable, else what is wrong with it (one line).

    Pixel coordinates must be finite and within one image size of the image.
    """
    if len(obs.centre_px) != 2 or not _finite(tuple(obs.centre_px)):
        return f"centre_px must be two finite numbers, got {obs.centre_px!r}"
    if len(obs.box_wh_px) != 2 or not _finite(tuple(obs.box_wh_px)):
        return f"box_wh_px must be two finite numbers, got {obs.box_wh_px!r}"
    if min(obs.box_wh_px) < 0:
        return f"box_wh_px must not be negative, got {obs.box_wh_px!r}"
    if not _finite((obs.confidence,)) or not 0.0 <= obs.confidence <= 1.0:
        return f"confidence must be in 0..1, got {obs.confidence!r}"
    if obs.corners_px is not None:
        flat = tuple(v for c in obs.corners_px for v in c)
        if len(obs.corners_px) != 4 or len(flat) != 8:
            return f"corners_px must be four (u, v) pairs, got {len(obs.corners_px)}"
        if not _finite(flat):
            return "corners_px contains a value that is not finite"
    measured = obs.corners_measured
    if measured is not None and (obs.corners_px is None or len(measured) != 4
                                 or not any(measured)):
        return "corners_measured must flag four corners_px, at least one of them measured"
    out = obs.extrapolated_sigma_px
    if out is not None and (measured is None or not _finite((out,)) or out <= 0.0):
        return f"extrapolated_sigma_px must be finite, > 0 and beside corners_measured, got {out!r}"
    sigma = obs.corner_sigma_px
    if sigma is not None and (not _finite((sigma,)) or sigma <= 0.0):
        return f"corner_sigma_px must be finite and > 0, got {sigma!r}"
    scale = obs.corner_scale_sigma_px
    if scale is not None and (not _finite((scale,)) or scale < 0.0):
        return f"corner_scale_sigma_px must be finite and >= 0, got {scale!r}"
    if obs.signature is not None and not _finite(tuple(obs.signature)):
        return "signature contains a value that is not finite"
    # an unmeasured corner may lie anywhere, unless it is used (extrapolated_sigma_px)
    flags = (True,) * 4 if out is not None else obs.corners_measured or (True,) * 4
    pts = [obs.centre_px, *(c for c, m in zip(obs.corners_px or (), flags, strict=False) if m)]
    if any(
        not (-width_px <= u <= 2 * width_px and -height_px <= v <= 2 * height_px) for u, v in pts
    ):
        return "a pixel coordinate lies more than one image size outside the image"
    if max(obs.box_wh_px) > 3 * max(width_px, height_px):
        return f"box_wh_px {obs.box_wh_px!r} is larger than three image sizes"
    return ""


def fresh_samples(
    time_us: int,
    attitude: AttitudeSample | None,
    altitude: AltitudeSample | None,
    laser: RangeSample | None,
    config: PoseConfig,
    notes: list[str],
) -> tuple[AttitudeSample | None, AltitudeSample | None, RangeSample | None]:
    """Drop side samples that are stale, non-finite or impossible (saying so in ``notes``)."""
    max_age_us = config.max_sample_age_s * 1e6

    def keep(name: str, t_us: int, values: tuple[float, ...]) -> bool:
        if not _finite(values):
            notes.append(f"{name} sample ignored: not finite")
            return False
        if abs(time_us - t_us) > max_age_us:
            age_ms = abs(time_us - t_us) / 1e3
            notes.append(f"{name} sample ignored: {age_ms:.0f} ms from the frame")
            return False
        return True

    if attitude is not None and not keep(
        "attitude",
        attitude.time_us,
        (
            attitude.roll_rad,
            attitude.pitch_rad,
            attitude.yaw_rad,
            attitude.roll_pitch_sigma_rad,
            attitude.yaw_sigma_rad,
        ),
    ):
        attitude = None
    if altitude is not None and not keep(
        "altitude", altitude.time_us, (altitude.down_m, altitude.sigma_m)
    ):
        altitude = None
    if laser is not None:
        ok = keep("laser", laser.time_us, (laser.distance_m, laser.sigma_m, *laser.axis_body))
        if ok and (laser.distance_m <= 0 or math.hypot(*laser.axis_body) < 1e-6):
            notes.append("laser sample ignored: distance <= 0 or zero axis")
            ok = False
        laser = laser if ok else None
    return attitude, altitude, laser
