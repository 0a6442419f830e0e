"""Assembling a flight: the parts ``companion run`` and ``companion demo`` share.

:func:`load_practical_map` turns the configured landmark map into the pose solver's map
(local NED about the EKF origin) and the appearance references the acquisition looks for;
:func:`fly` wires a source, a perception and a bridge into a :class:`CompanionApp`, runs
it until the source ends, a signal or a time limit, and tears everything down in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.app import CompanionApp, Frame, FrameResult, FrameSource
from companion.autopilot import AttitudeHistory, BridgeSink
from companion.errors import ConfigError, InputError
from companion.flightlog import FlightLogWriter
from companion.landmarks.geodesy import LocalFrame
from companion.landmarks.geojson_io import read_map
from companion.landmarks.record import Landmark
from companion.monitoring.publisher import MonitorPublisher
from companion.perception import DetectFn, Perception, PerceptionWrapper, SideSensors
from companion.preview import render_preview
from companion.reporting import Reporter
from companion.settings import Settings
from companion.validate import to_plain
from mavlink_bridge.bridge import VisionBridge, create_bridge
from mavlink_bridge.streams import needed_streams
from tracker.camera import CameraModel
from tracker.detector import Detector, DetectorConfig, DetectorError
from tracker.pose.types import MapLandmark

ImageU8 = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class PracticalMap:
    """The landmarks of this flight in local NED, and the images to look for."""

    landmarks: tuple[MapLandmark, ...]
    references: dict[str, ImageU8]
    origin: LocalFrame


def reference_image(lm: Landmark) -> ImageU8 | None:
    """The landmark's appearance reference, cropped to its box, or None."""
    if lm.appearance is None:
        return None
    image = cv2.imdecode(np.frombuffer(lm.appearance.data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise InputError(f"landmark {lm.id}: appearance: cannot decode the image")
    if lm.appearance.box_px is not None:
        x, y, w, h = lm.appearance.box_px
        image = image[y:y + h, x:x + w]
    return np.asarray(image, np.uint8)


def load_practical_map(settings: Settings) -> PracticalMap:
    """Read ``landmarks.map_path`` and place it about the configured EKF origin."""
    mav = settings.mavlink
    if mav.origin_lat_deg == 0.0 and mav.origin_lon_deg == 0.0:
        raise ConfigError("mavlink.origin_lat_deg, mavlink.origin_lon_deg: expected the EKF "
                          "origin (WGS84) that the landmark map is placed about, got 0, 0")
    path = settings.landmarks.map_path
    if not path or not Path(path).is_file():
        raise InputError(f"{path or 'landmarks.map_path'}: no landmark map (set "
                         "landmarks.map_path to a GeoJSON file: companion landmarks export "
                         "writes one)")
    frame = LocalFrame(mav.origin_lat_deg, mav.origin_lon_deg, mav.origin_alt_m)
    records = [lm for lm in read_map(path) if lm.status != "rejected"]
    landmarks, references = [], {}
    for lm in records:
        n, e, d = (float(v) for v in frame.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m))
        landmarks.append(MapLandmark(lm.id, (n, e, d), lm.width_m, lm.height_m,
                                     lm.facing_deg, lm.category))
        image = reference_image(lm)
        if image is not None:
            references[lm.id] = image
    return PracticalMap(tuple(landmarks), references, frame)


def reporter_for(settings: Settings, landmarks: tuple[MapLandmark, ...] | list[MapLandmark],
                 prefix: str) -> Reporter:
    """Flight log in ``flightlog.dir`` and, when enabled, Zenoh monitoring."""
    name = time.strftime(f"{prefix}-%Y%m%d-%H%M%S.jsonl")
    flightlog = FlightLogWriter(Path(settings.flightlog.dir) / name, settings.vehicle.id,
                                settings.flightlog.fsync_interval_s)
    monitor = None
    if settings.monitor.enabled:
        providers: dict[str, Callable[[], Any]] = {
            "config": lambda: to_plain(settings),
            "landmarks": lambda: [{"id": lm.landmark_id, "category": lm.category,
                                   "position_ned_m": list(lm.position_ned_m),
                                   "width_m": lm.width_m, "height_m": lm.height_m,
                                   "facing_deg": lm.facing_deg} for lm in landmarks],
        }
        monitor = MonitorPublisher(settings.monitor, settings.vehicle.id, providers)
    return Reporter(flightlog, monitor)


@functools.lru_cache(maxsize=4)
def _detector(config: DetectorConfig) -> Detector:
    """One loaded model per configuration (loading takes tens of ms; sessions are shared)."""
    return Detector(config=config)


def detector_for(settings: Settings) -> DetectFn | None:
    """The landmark detector when ``perception.use_detector``; a bad model is one line.

    The model is loaded once per configuration, so calling this before a camera's clock
    starts keeps the load out of the first frame's time."""
    if not settings.perception.use_detector:
        return None
    try:
        return _detector(settings.detector).detect
    except DetectorError as err:
        raise InputError(str(err)) from None


def perception_for(settings: Settings, camera: CameraModel, pmap: PracticalMap,
                   attitude: AttitudeHistory) -> Perception:
    """The per-frame work with the configured tracker, acquisition, pose and gate."""
    return Perception(camera, pmap.landmarks, pmap.references, detect=detector_for(settings),
                      sensors=lambda t_us: SideSensors(attitude=attitude.at(t_us)),
                      config=settings.perception, tracker_config=settings.tracker,
                      pose_config=settings.pose, acquire_config=settings.acquire,
                      gate_config=settings.fixgate)


async def fly(settings: Settings, source: FrameSource, bridge: VisionBridge,
              make_processor: Callable[[AttitudeHistory], Perception | PerceptionWrapper],
              landmarks: tuple[MapLandmark, ...] | list[MapLandmark], *,
              seconds: float | None = None, prefix: str = "flight",
              on_start: Callable[[CompanionApp], None] | None = None) -> CompanionApp:
    """Run one flight to its end; SIGINT/SIGTERM stop it cleanly.  Returns the app.

    Everything that can fail on bad input (the processor: a detector model, references)
    is built before anything is started, so such a failure leaves nothing running.
    OpenCV runs single-threaded: the pipeline's own threads use the cores
    (``companion.LIBRARY_THREAD_VARS`` says why).
    """
    cv2.setNumThreads(1)
    attitude = AttitudeHistory(bridge)
    processor = make_processor(attitude)
    mon = settings.monitor

    def preview(frame: Frame, result: FrameResult) -> bytes:
        caption = "fix" if result.fix is not None else (result.no_fix_reason or "")[:60]
        tracks = [{**t, "particles": result.particles.get(t["landmark_id"], ())}
                  for t in result.tracks]
        return render_preview(frame.image, tracks, mon.preview_width_px,
                              mon.preview_jpeg_quality, caption)

    try:
        reporter = reporter_for(settings, landmarks, prefix)
    except BaseException:
        processor.close()
        raise
    loop = asyncio.get_running_loop()
    try:
        await bridge.start()
        attitude.start()
        app = CompanionApp(source, processor, BridgeSink(bridge), reporter,
                           settings.vehicle.id, 1.0 / mon.status_rate_hz, preview=preview)
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, app.request_stop)
        if on_start is not None:
            on_start(app)
        await app.run(seconds)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.remove_signal_handler(sig)
        close = getattr(source, "close", None)
        if callable(close):
            close()
        await attitude.stop()
        await bridge.stop()
        reporter.close()
        processor.close()
    return app


def stream_rates(settings: Settings) -> tuple[tuple[str, float], ...]:
    """The messages this configuration needs from the autopilot, as (name, Hz)
    (:func:`mavlink_bridge.streams.needed_streams` decides; docs/mavlink.md)."""
    from companion.sources.factory import resolve

    try:
        source = resolve(settings.source)
    except InputError:  # the source's own open says what is wrong with it
        source = settings.source
    follow = source.kind == "follow"
    fps = (source.follow.fps or source.fps) if follow else source.fps
    specs = needed_streams(fps, profile=settings.vehicle.profile,
                           rangefinder=settings.pose.rangefinder, follow=follow)
    return tuple((s.name, s.rate_hz) for s in specs)


def bridge_for(settings: Settings, **overrides: Any) -> VisionBridge:
    """The configured MAVLink backend, its profile following ``vehicle.profile``, asking for
    the streams the configuration needs."""
    import dataclasses

    overrides.setdefault("streams", stream_rates(settings))
    cfg = dataclasses.replace(settings.mavlink, profile=settings.vehicle.profile, **overrides)
    return create_bridge(cfg)
