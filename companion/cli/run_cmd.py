"""``companion run``: the real deployment -- a camera and a serial or UDP autopilot link."""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import sys

from companion.app import CompanionApp, Frame, FrameResult, FrameSource
from companion.autopilot import AttitudeHistory
from companion.perception import Perception, PerceptionWrapper
from companion.runtime import PracticalMap, bridge_for, fly, load_practical_map, perception_for
from companion.settings import Settings
from companion.sim.follow import FollowCameraSource, command_sender, follow_simulator
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sim.square import FlightAbortedError, SquareFlight
from companion.sources.factory import open_source, resolve
from mavlink_bridge.bridge import VisionBridge

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion run``."""
    parser = sub.add_parser(
        "run", help="fly: camera -> trackers -> pose -> MAVLink to the autopilot",
        description="Run the companion with the configured source ([source]), landmark map "
        "([landmarks] map_path), autopilot link ([mavlink]) and monitoring ([monitor]) until "
        "SIGINT/SIGTERM or the end of a finite source.  docs/deploy.md has a systemd unit.",
    )
    parser.add_argument("--seconds", type=float, help="stop after this many seconds")
    parser.add_argument("--fly", action="store_true",
                        help="SITL only: arm (GUIDED / OFFBOARD) and fly a small square with "
                        "position targets so the loop runs while moving (docs/sitl.md)")
    parser.set_defaults(handler=run)


def simulator_of(source: object) -> Simulator | None:
    """The simulator behind a simulated camera (scripted or following SITL), else None."""
    sim = getattr(source, "sim", None)
    return sim if isinstance(sim, Simulator) else None


def with_sim_references(pmap: PracticalMap, source: object) -> PracticalMap:
    """A simulated camera shows generated textures: use them where the map has no image."""
    sim = simulator_of(source)
    if sim is None:
        return pmap
    textures = {lm.landmark_id: lm.quad.texture for lm in sim.world.landmarks
                if lm.quad.texture is not None}
    refs = {**{k: v for k, v in textures.items() if k not in pmap.references},
            **pmap.references}
    return PracticalMap(pmap.landmarks, refs, pmap.origin)


class TruthTagger(PerceptionWrapper):
    """Follow mode: each pose message also carries the true position the frame showed
    (``truth_position_ned_m``) and the fix's distance from it (``truth_error_m``)."""

    def __init__(self, perception: Perception, source: FollowCameraSource) -> None:
        super().__init__(perception)
        self.source = source

    def process(self, frame: Frame) -> FrameResult:
        result = self.perception.process(frame)
        state = self.source.rendered_state(frame.index)
        if result.fix is not None and result.pose_json is not None and state is not None:
            truth = state.position_ned_m
            result.pose_json["truth_position_ned_m"] = [round(v, 4) for v in truth]
            result.pose_json["truth_error_m"] = round(
                math.dist(result.fix.position_ned_m, truth), 4)
        return result


def open_follow(settings: Settings, bridge: VisionBridge, pmap: PracticalMap
                ) -> FollowCameraSource:
    """``source.kind = "follow"``: the scenario's world with the flight's landmark map about
    the EKF origin, seen from the pose the autopilot simulator reports (docs/sitl.md)."""
    c = resolve(settings.source)
    sim = follow_simulator(load_scenario(c.spec), settings.landmarks.map_path, pmap.origin)
    return FollowCameraSource(sim, bridge, pmap.origin, settings.vehicle.profile, c.follow,
                              request=command_sender(bridge))


async def _run(settings: Settings, seconds: float | None, fly_square: bool = False
               ) -> CompanionApp:
    pmap = load_practical_map(settings)
    bridge = bridge_for(settings)
    source: FrameSource
    if resolve(settings.source).kind == "follow":
        source = open_follow(settings, bridge, pmap)
    else:
        source = await open_source(settings.source)
    pmap = with_sim_references(pmap, source)
    sim = simulator_of(source)
    camera = sim.scenario.camera if sim is not None else settings.camera
    log.info("flying with %d landmarks (%d with a reference image), source %s:%s",
             len(pmap.landmarks), len(pmap.references), settings.source.kind,
             settings.source.spec)

    def processor(attitude: AttitudeHistory) -> Perception | PerceptionWrapper:
        perception = perception_for(settings, camera, pmap, attitude)
        if isinstance(source, FollowCameraSource):
            return TruthTagger(perception, source)
        return perception

    flights: list[asyncio.Task[None]] = []

    def start_flying(app: CompanionApp) -> None:
        link = getattr(bridge, "link", None)
        if link is None:
            log.error("--fly needs mavlink.backend = \"pymavlink\"; not flying")
            return
        square = SquareFlight(link, bridge.latest, settings.vehicle.profile)
        flights.append(asyncio.create_task(square.run(), name="fly-square"))
        flights[0].add_done_callback(lambda task: _flight_ended(task, app))

    try:
        app = await fly(settings, source, bridge, processor, pmap.landmarks, seconds=seconds,
                        prefix="run", on_start=start_flying if fly_square else None)
    finally:
        for task in flights:
            task.cancel()
        outcomes = await asyncio.gather(*flights, return_exceptions=True)
    failure = getattr(source, "failure", None)
    if failure is not None:  # e.g. follow mode without the simulator's truth: one line
        raise failure
    aborted = [o for o in outcomes if isinstance(o, FlightAbortedError)]
    if aborted:  # the vehicle left the square's control: say why, exit non-zero
        raise aborted[0]
    return app


def _flight_ended(task: asyncio.Task[None], app: CompanionApp) -> None:
    """--fly ended by itself: a disarm, mode change or failsafe stops the companion too."""
    if task.cancelled() or task.exception() is None:
        return
    log.error("%s", task.exception())
    if isinstance(task.exception(), FlightAbortedError):
        app.request_stop()


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Fly until stopped; exit status 0 on a clean stop."""
    app = asyncio.run(_run(settings, args.seconds, getattr(args, "fly", False)))
    c = app.counters
    log.info("stopped: %d frames, %d fixes sent, %d dropped frames", c.frames, c.fixes_sent,
             app.dropped_frames)
    if c.worker_errors:  # a bug, logged with its traceback: not a clean stop
        print("companion: frame processing failed (see the log above)", file=sys.stderr)
        return 1
    return 0
