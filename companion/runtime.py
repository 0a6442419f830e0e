"""Assembling a flight: the one place ``companion run``, ``demo``, ``replay`` and the SITL
harness build one.

The flight's landmark map comes from :mod:`companion.flightmap`; :class:`CompanionFlight`
wires a source, a perception, a bridge and the observers of the results into a
:class:`CompanionApp`, runs it until the source ends, a signal or a time limit, and tears
everything down in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2

from companion.app import CompanionApp, Frame, FrameResult, FrameSource, ResultObserver, now_us
from companion.autopilot import BridgeSink
from companion.core.validate import to_plain
from companion.errors import ConfigError, InputError, note_stop_signal
from companion.flightlog import FlightLogWriter
from companion.flightmap import PracticalMap, acquisition_report, log_report, static_blocker
from companion.monitoring.config import MonitorConfig
from companion.monitoring.publisher import MonitorPublisher
from companion.nofix import AttitudeSource, NoFixWatch
from companion.perception import DetectFn, Perception
from companion.preview import render_preview
from companion.reporting import Reporter, track_json
from companion.sensors import SensorHistory
from companion.settings import Settings
from mavlink_bridge.bridge import VisionBridge, create_bridge
from mavlink_bridge.errors import BackendError
from mavlink_bridge.streams import StreamSpec, needed_streams
from tracker.camera import CameraModel
from tracker.detector import Detector, DetectorConfig, DetectorError
from tracker.pose.types import MapLandmark

__all__ = ["CompanionFlight", "PracticalMap", "bridge_for", "detector_for", "noise_status",
           "perception_for"]


log = logging.getLogger(__name__)

def reporter_for(settings: Settings, landmarks: tuple[MapLandmark, ...] | list[MapLandmark],
                 prefix: str) -> Reporter:
    """Flight log in ``flightlog.dir`` and, when enabled, Zenoh monitoring."""
    name = time.strftime(f"{prefix}-%Y%m%d-%H%M%S.jsonl")  # the writer makes it unique
    fl = settings.flightlog
    flightlog = FlightLogWriter(Path(fl.dir) / name, settings.vehicle.id, fl.fsync_interval_s,
                                max_file_bytes=round(fl.max_file_mb * 1e6))
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
                   sensors: SensorHistory) -> Perception:
    """The per-frame work with the configured tracker, acquisition, pose and gate."""
    return Perception(camera, pmap.landmarks, pmap.references, detect=detector_for(settings),
                      sensors=sensors,
                      config=settings.perception, tracker_config=settings.tracker,
                      pose_config=settings.pose, acquire_config=settings.acquire,
                      gate_config=settings.fixgate)


class CompanionFlight:
    """One flight, assembled here and nowhere else (docs/architecture.md, "Who assembles a
    flight").

    The caller chooses what differs between ``companion run``, ``demo``, ``replay`` and the
    SITL harness: the frame ``source``, the ``bridge``, the map, the ``camera`` that took the
    frames, where the frames' attitude comes from (``attitude``; None: the autopilot's
    ATTITUDE through the bridge) and who observes the results (:meth:`observe`).  The
    flight builds the rest -- the side sensors (:attr:`sensors`, there from the start for
    an observer that scores what the solver was given), the perception, the reporter
    (flight log named ``prefix``-..., Zenoh), the bridge's sink, the no-fix diagnosis and
    the :class:`CompanionApp` -- and :meth:`run` flies it to its end.
    """

    def __init__(self, settings: Settings, source: FrameSource, bridge: VisionBridge,
                 pmap: PracticalMap, camera: CameraModel, *,
                 attitude: AttitudeSource | None = None, prefix: str = "flight",
                 clock_us: Callable[[], int] | None = None) -> None:
        self.settings = settings
        #: the frames' clock when not the machine's monotonic one (:class:`CompanionApp`)
        self.clock_us = clock_us
        self.source = source
        self.bridge = bridge
        self.pmap = pmap
        self.camera = camera
        self.prefix = prefix
        self.sensors = SensorHistory(bridge, settings.pose, attitude=attitude)
        self.observers: list[ResultObserver] = []
        self.app: CompanionApp | None = None

    def observe(self, *observers: ResultObserver) -> None:
        """Subscribe ``observers`` to the results; they are called in the order added."""
        self.observers.extend(observers)

    async def run(self, seconds: float | None = None,
                  on_start: Callable[[CompanionApp], None] | None = None) -> CompanionApp:
        """Run the flight to its end; SIGINT/SIGTERM stop it cleanly.  Returns the app.

        Everything that can fail on bad input (the perception: a detector model,
        references) is built before anything is started, so such a failure leaves nothing
        running.  The map's acquisition report is logged, published (an ``map`` event and
        the status' ``map``) and, with the bridge and the attitude, feeds the diagnosis of
        why no fix can come (:class:`companion.nofix.NoFixWatch`).  OpenCV runs
        single-threaded: the pipeline's own threads use the cores (``companion.launch``
        says why).  The source is closed at the end.
        """
        cv2.setNumThreads(1)
        settings, bridge, sensors = self.settings, self.bridge, self.sensors
        perception = perception_for(settings, self.camera, self.pmap, sensors)
        try:
            report, watch = _diagnosis(settings, self.pmap, perception, bridge, sensors)
        except BaseException:
            perception.close()
            raise
        mon = settings.monitor
        loop = asyncio.get_running_loop()
        reporter: Reporter | None = None
        try:
            await bridge.start()  # first: a link that cannot open leaves no empty flight log
            reporter = reporter_for(settings, self.pmap.landmarks, self.prefix)
            sensors.start()
            self.app = app = CompanionApp(
                self.source, perception, BridgeSink(bridge), reporter, settings.vehicle.id,
                1.0 / mon.status_rate_hz, preview=preview_for(mon), diagnose=watch,
                facts={"map": _map_summary(report), "noise": noise_status(settings)},
                observers=self.observers, clock_us=self.clock_us or now_us)
            app.report_event("map", report)
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError):
                    loop.add_signal_handler(sig, _stop_by_signal, app, sig)
            if on_start is not None:
                on_start(app)
            await app.run(seconds)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError):
                    loop.remove_signal_handler(sig)
            close = getattr(self.source, "close", None)
            if callable(close):
                close()
            await sensors.stop()
            await bridge.stop()
            if reporter is not None:
                reporter.close()
            perception.close()
        return app


def stream_specs(settings: Settings, profile: str | None = None) -> tuple[StreamSpec, ...]:
    """The messages this configuration needs from the autopilot (``profile``: instead of
    ``vehicle.profile``; :func:`mavlink_bridge.streams.needed_streams` decides)."""
    from companion.sources.factory import resolve

    try:
        source = resolve(settings.source)
    except InputError:  # the source's own open says what is wrong with it
        source = settings.source
    follow = source.kind == "follow"
    fps = (source.follow.fps or source.fps) if follow else source.fps
    return needed_streams(fps, profile=profile or settings.vehicle.profile,
                          rangefinder=settings.pose.rangefinder, follow=follow)


def stream_rates(settings: Settings) -> tuple[tuple[str, float], ...]:
    """:func:`stream_specs` as (name, Hz) for ``MavlinkConfig.streams`` (docs/mavlink.md)."""
    return tuple((s.name, s.rate_hz) for s in stream_specs(settings))


def preview_for(mon: MonitorConfig) -> Callable[[Frame, FrameResult], bytes]:
    """Draws a frame's preview (boxes, particles, the fix or why there is none)."""
    def preview(frame: Frame, result: FrameResult) -> bytes:
        caption = "fix" if result.fix is not None else (result.no_fix_reason or "")[:60]
        tracks = [{**track_json(t), "particles": result.particles.get(t.landmark_id, ())}
                  for t in result.tracks]
        return render_preview(frame.image, tracks, mon.preview_width_px,
                              mon.preview_jpeg_quality, caption)
    return preview


def _diagnosis(settings: Settings, pmap: PracticalMap, perception: Perception,
               bridge: VisionBridge, attitude: AttitudeSource
               ) -> tuple[dict[str, Any], NoFixWatch]:
    """The map's acquisition report (logged) and the watch that names why no fix comes."""
    report = acquisition_report(pmap, perception)
    log_report(report)
    static = static_blocker(pmap, report, settings.landmarks.max_origin_distance_m)
    return report, NoFixWatch(static, bridge, attitude, perception.camera, pmap.landmarks,
                              settings.mavlink.endpoint)


def _map_summary(report: dict[str, Any]) -> dict[str, Any]:
    """The status' ``map``: counts and the reasons, not the full lists of ids."""
    return {"from": report["from"], "loaded": len(report["loaded"]),
            "with_reference": len(report["with_reference"]),
            "cannot_acquire": report["cannot_acquire"]}


def noise_status(settings: Settings) -> str:
    """``"measured"``, or ``"uncalibrated"`` (logged as a warning) while the pixel noise is
    the deployment's conservative default: the covariance sent is then a guess."""
    if settings.noise_measured:
        return "measured"
    log.warning("uncalibrated noise: pose.pixel_sigma_px = %g is the conservative default, "
                "not measured on this camera (docs/deploy.md: companion calibrate noise)",
                settings.pose.pixel_sigma_px)
    return "uncalibrated"


def _stop_by_signal(app: CompanionApp, signum: int) -> None:
    note_stop_signal(signum)  # the CLI exits 128 + signum once the flight is wound down
    app.request_stop()


def bridge_for(settings: Settings, clock_ns: Callable[[], int] | None = None,
               **overrides: Any) -> VisionBridge:
    """The configured MAVLink backend, its profile following ``vehicle.profile``, asking for
    the streams the configuration needs (``clock_ns``: :func:`create_bridge`'s)."""
    import dataclasses

    overrides.setdefault("streams", stream_rates(settings))
    cfg = dataclasses.replace(settings.mavlink, profile=settings.vehicle.profile, **overrides)
    try:
        return create_bridge(cfg, clock_ns)
    except BackendError as err:  # e.g. the mavsdk extra is not installed: one line
        raise ConfigError(str(err)) from None
