"""``companion demo``: the whole program on one machine, nothing to install or start.

The simulated camera flies a scenario over the landmarks of ``config/landmarks.geojson``;
the scripted fake autopilot flies the *same* trajectory on UDP loopback and judges every
vision message by ArduPilot's or PX4's rules; the companion tracks, solves and sends
fixes over MAVLink, publishes on Zenoh in-process and writes a flight log.  At the end a
summary compares every fix with the simulated truth.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.app import CompanionApp
from companion.autopilot import BridgeSink, attitude_sample
from companion.flightlog import FlightLogWriter
from companion.monitoring.publisher import MonitorPublisher
from companion.perception import Perception, SideSensors
from companion.reporting import Reporter
from companion.settings import Settings
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource
from companion.validate import to_plain
from mavlink_bridge.bridge import VisionBridge, create_bridge
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.vehicle import VehicleState as AutopilotState
from tracker.pose.types import MapLandmark, PoseFix

log = logging.getLogger(__name__)


@dataclass
class DemoResult:
    """Everything the summary needs, gathered while the demo runs."""

    fixes: list[tuple[PoseFix, tuple[float, float, float], float]]  # fix, truth, distance


class TruthRecorder:
    """Wraps the perception to remember, for every fix, where the vehicle truly was."""

    def __init__(self, perception: Perception, source: SimCameraSource,
                 landmarks: dict[str, MapLandmark]) -> None:
        self.perception = perception
        self.source = source
        self.landmarks = landmarks
        self.result = DemoResult([])

    def process(self, frame: Any) -> Any:
        result = self.perception.process(frame)
        if isinstance(result.fix, PoseFix):
            state = self.source.sim.state_at(self.source.scenario_time_s(frame))
            truth = tuple(float(v) for v in state.position_ned_m)
            used = [self.landmarks[i] for i in result.fix.landmark_ids if i in self.landmarks]
            dist = float(np.mean([math.dist(truth, lm.position_ned_m) for lm in used])) \
                if used else float("nan")
            self.result.fixes.append((result.fix, truth, dist))  # type: ignore[arg-type]
            if result.pose_json is not None:
                result.pose_json["truth_position_ned_m"] = [round(v, 4) for v in truth]
        return result


def map_landmarks(sim: Simulator) -> tuple[list[MapLandmark], dict[str, np.ndarray]]:
    """The practical map (NED) and appearance references of the simulated world."""
    landmarks, references = [], {}
    for lm in sim.world.landmarks:
        landmarks.append(MapLandmark(lm.landmark_id, tuple(float(v) for v in lm.centre_ned),
                                     lm.width_m, lm.height_m, lm.facing_deg, lm.category))
        if lm.quad.texture is not None:
            references[lm.landmark_id] = lm.quad.texture
    return landmarks, references


def autopilot_truth(source: SimCameraSource) -> Callable[[float], AutopilotState]:
    """The fake autopilot flies what the camera sees: the scenario clock of the source."""

    def truth(_time_s: float) -> AutopilotState:
        t0 = source.t0_us
        t = 0.0 if t0 is None else max(0.0, (time.monotonic_ns() // 1000 - t0) / 1e6)
        s = source.sim.state_at(t)
        rng = source.sim.rangefinder.measure(s, np.random.default_rng(int(t * 1000)))
        return AutopilotState(t, s.position_ned_m, s.velocity_ned_m_s, s.attitude_rpy_rad,
                              float(rng) if rng is not None else float("nan"))

    return truth


async def run_demo(settings: Settings, scenario: str, seconds: float,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the embedded demo and return its summary (see :func:`summary`)."""
    sim = Simulator(dataclasses.replace(load_scenario(scenario), seconds=seconds))
    source = SimCameraSource(sim, realtime=True, seconds=seconds)
    landmarks, references = map_landmarks(sim)
    origin = sim.scenario.origin
    fake = FakeAutopilot(FakeAutopilotConfig(profile=settings.vehicle.profile,
                                             endpoint="udpin:127.0.0.1:0"),
                         truth=autopilot_truth(source))
    await fake.start()
    mav_cfg = dataclasses.replace(
        settings.mavlink, profile=settings.vehicle.profile,
        endpoint=f"udpout:127.0.0.1:{fake.local_port}", origin_lat_deg=origin.lat,
        origin_lon_deg=origin.lon, origin_alt_m=origin.alt_m, set_origin=True)
    bridge = create_bridge(mav_cfg)
    await bridge.start()
    await bridge.wait_link(True, timeout_s=5.0)
    perception = Perception(sim.scenario.camera, landmarks, references,
                            sensors=lambda: SideSensors(attitude=attitude_sample(bridge)),
                            config=settings.perception, tracker_config=settings.tracker,
                            pose_config=settings.pose, acquire_config=settings.acquire)
    recorder = TruthRecorder(perception, source, {lm.landmark_id: lm for lm in landmarks})
    reporter = _reporter(settings, landmarks)
    app = CompanionApp(source, recorder, BridgeSink(bridge), reporter, settings.vehicle.id)
    cpu0, wall0 = os.times(), time.monotonic()
    ticker = asyncio.create_task(_progress(app, fake, seconds, progress))
    try:
        await app.run(seconds + 5.0)
    finally:
        ticker.cancel()
        await asyncio.gather(ticker, return_exceptions=True)
        cpu1, wall1 = os.times(), time.monotonic()
        await bridge.stop()
        await fake.stop()
        reporter.close()
    busy = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / max(wall1 - wall0, 1e-9)
    return summary(app, fake, bridge, recorder.result, source, busy)


def _reporter(settings: Settings, landmarks: list[MapLandmark]) -> Reporter:
    log_dir = Path(settings.flightlog.dir)
    name = time.strftime("demo-%Y%m%d-%H%M%S.jsonl")
    flightlog = FlightLogWriter(log_dir / name, settings.vehicle.id,
                                settings.flightlog.fsync_interval_s)
    monitor = None
    if settings.monitor.enabled:
        providers = {
            "config": lambda: to_plain(settings),
            "landmarks": lambda: [{"id": lm.landmark_id, "category": lm.category,
                                   "position_ned_m": list(lm.position_ned_m),
                                   "width_m": lm.width_m, "height_m": lm.height_m,
                                   "facing_deg": lm.facing_deg} for lm in landmarks],
        }
        monitor = MonitorPublisher(settings.monitor, settings.vehicle.id, providers)
    return Reporter(flightlog, monitor)


async def _progress(app: CompanionApp, fake: FakeAutopilot, seconds: float,
                    progress: Callable[[str], None] | None) -> None:
    if progress is None:
        return
    start = time.monotonic()
    while True:
        await asyncio.sleep(0.5)
        s = app.status()
        lat = s["latency_ms"]["p50"]
        progress(f"{time.monotonic() - start:5.1f}/{seconds:.0f} s  {s['state']:<9} "
                 f"frames {s['counters']['frames']:5d}  fps {s['fps']:5.1f}  "
                 f"fixes {s['counters']['fixes_sent']:5d} (accepted "
                 f"{len(fake.accepted()):5d})  latency p50 "
                 f"{'-' if lat is None else f'{lat:.1f}'} ms  dropped {s['dropped_frames']}")


def summary(app: CompanionApp, fake: FakeAutopilot, bridge: VisionBridge, result: DemoResult,
            source: SimCameraSource, cpu_cores_busy: float) -> dict[str, Any]:
    """The demo's numbers: the keys the README and the issue name, and a few more."""
    errors = [math.dist(fix.position_ned_m, truth) for fix, truth, _ in result.fixes]
    dists = [d for _, _, d in result.fixes if math.isfinite(d)]
    rmse = float(np.sqrt(np.mean(np.square(errors)))) if errors else None
    mean_dist = float(np.mean(dists)) if dists else None
    lat = app.stats.capture_to_wire_ms
    sent = app.counters.fixes_sent
    accepted = len(fake.accepted())
    return {
        "frames": app.counters.frames,
        "fps": round(app.counters.frames / max(source.seconds, 1e-9), 2),
        "fixes_sent": sent,
        "fixes_accepted": accepted,
        "fixes_accepted_ratio": round(accepted / sent, 4) if sent else None,
        "position_rmse_m": None if rmse is None else round(rmse, 4),
        "mean_landmark_distance_m": None if mean_dist is None else round(mean_dist, 2),
        "position_rmse_pct_of_distance": None if not (rmse and mean_dist)
        else round(100 * rmse / mean_dist, 3),
        "latency_p50_ms": lat.summary()["p50"],
        "latency_p99_ms": lat.summary()["p99"],
        "dropped_frames": app.dropped_frames + source.status.skipped,
        "cpu_cores_busy": round(cpu_cores_busy, 3),
        "no_fix_frames": app.counters.no_fix,
        "autopilot_rejections": fake.summary()["vision_reasons"],
        "bridge": {k: v for k, v in bridge.stats().items() if isinstance(v, int | float | str)},
    }


def print_summary(s: dict[str, Any], out: Any = sys.stdout) -> None:
    """The human-readable end of ``companion demo``."""
    def f(v: Any, unit: str = "") -> str:
        return "-" if v is None else f"{v}{unit}"

    lines = [
        f"frames            {s['frames']}  ({f(s['fps'])} fps, {s['dropped_frames']} dropped)",
        f"fixes sent        {s['fixes_sent']}",
        f"fixes accepted    {s['fixes_accepted']} by the fake autopilot "
        f"({f(s['fixes_accepted_ratio'] and round(100 * s['fixes_accepted_ratio'], 1), ' %')})",
        f"position RMSE     {f(s['position_rmse_m'], ' m')} at a mean "
        f"{f(s['mean_landmark_distance_m'], ' m')} from the landmarks "
        f"({f(s['position_rmse_pct_of_distance'], ' %')})",
        f"latency           p50 {f(s['latency_p50_ms'], ' ms')}  p99 "
        f"{f(s['latency_p99_ms'], ' ms')} (capture -> on the wire)",
        f"cpu               {s['cpu_cores_busy']} cores busy on average",
    ]
    print("\n".join(lines), file=out)
