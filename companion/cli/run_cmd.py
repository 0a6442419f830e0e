"""``companion run``: the real deployment -- a camera and a serial or UDP autopilot link."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from companion.app import CompanionApp, Frame, FrameResult, FrameSource
from companion.autopilot import outcome_lines
from companion.cli import positive_seconds
from companion.config_checks import preflight
from companion.errors import EXIT_FAILURE, EXIT_OK, ConfigError, SourceError
from companion.flightmap import PracticalMap, load_practical_map
from companion.follow import FollowCameraSource, command_sender, follow_simulator
from companion.nofix import AttitudeSource
from companion.perception import Perception, PerceptionWrapper
from companion.recorded import (
    RECORDED_KINDS,
    OnCompanionClock,
    RecordedTruth,
    TruthAttitude,
    recording_camera,
)
from companion.runtime import bridge_for, fly, perception_for
from companion.sensors import SensorHistory
from companion.settings import Settings
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sim.square import FlightAbortedError, SquareFlight
from companion.simulated import open_sim
from companion.sources.factory import open_source, resolve
from companion.sources.files import RecordedStreamSource
from mavlink_bridge.bridge import VisionBridge
from tracker.camera import CameraModel

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion run``."""
    parser = sub.add_parser(
        "run", help="fly: camera -> trackers -> pose -> MAVLink to the autopilot",
        description="Run the companion with the configured source ([source]), landmark map "
        "(the practical map of [landmarks] db_path about the EKF origin, or the file "
        "[landmarks] map_path when set), autopilot link ([mavlink]) and monitoring "
        "([monitor]) until SIGINT/SIGTERM or the end of a finite source.  docs/deploy.md "
        "has a systemd unit.",
    )
    parser.add_argument("--seconds", type=positive_seconds, help="stop after this many seconds")
    parser.add_argument("--truth-attitude", action="store_true",
                        help="a recorded stream with truth_pose.csv: take the attitude from "
                        "it (with an autopilot's typical error) instead of the autopilot's "
                        "ATTITUDE, to check a recording offline (docs/formats.md)")
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
    unusable = {k: v for k, v in pmap.unusable.items() if k not in refs}
    return dataclasses.replace(pmap, references=refs, unusable=unusable)


#: The true position (flight NED, m) of the vehicle when a frame was taken, or None.
TruthOf = Callable[[Frame], Sequence[float] | None]


class TruthTagger(PerceptionWrapper):
    """Follow mode and recordings with truth: each pose message also carries the true
    position the frame showed (``truth_position_ned_m``) and the fix's distance from it
    (``truth_error_m``)."""

    def __init__(self, perception: Perception, truth_of: TruthOf) -> None:
        super().__init__(perception)
        self.truth_of = truth_of

    def process(self, frame: Frame) -> FrameResult:
        result = self.perception.process(frame)
        truth = self.truth_of(frame) if result.fix is not None else None
        if result.fix is not None and truth is not None:
            result.pose_extra["truth_position_ned_m"] = [round(v, 4) for v in truth]
            result.pose_extra["truth_error_m"] = round(
                math.dist(result.fix.position_ned_m, truth), 4)
        return result


def open_follow(settings: Settings, bridge: VisionBridge, pmap: PracticalMap
                ) -> FollowCameraSource:
    """``source.kind = "follow"``: the scenario's world with the flight's landmark map about
    the EKF origin, seen from the pose the autopilot simulator reports (docs/sitl.md)."""
    c = resolve(settings.source)
    if not settings.landmarks.map_path:
        raise ConfigError("source.kind = \"follow\": the simulated camera renders the landmarks "
                          "of landmarks.map_path: set it to the map the autopilot simulator's "
                          "world uses (docs/sitl.md)")
    sim = follow_simulator(load_scenario(c.spec), settings.landmarks.map_path, pmap.origin)
    return FollowCameraSource(sim, bridge, pmap.origin, settings.vehicle.profile, c.follow,
                              request=command_sender(bridge))


@dataclass(frozen=True)
class RunSource:
    """The frames of a run, the camera that took them, where their attitude comes from
    (None: the autopilot's ATTITUDE) and their true position when known."""

    source: FrameSource
    camera: CameraModel
    attitude: AttitudeSource | None = None
    truth_of: TruthOf | None = None


async def open_run_source(settings: Settings, bridge: VisionBridge, pmap: PracticalMap,
                          truth_attitude: bool = False) -> RunSource:
    """The configured source; a recording is put on the companion's clock, solved with its
    own camera and, with truth, scored against it (:mod:`companion.recorded`)."""
    c = resolve(settings.source)
    log.info("source %s:%s", c.kind, c.spec)
    if truth_attitude and c.kind != "stream":
        raise ConfigError(f"--truth-attitude: source {c.spec!r} is a {c.kind}, not a recorded "
                          "stream with truth_pose.csv")
    if c.kind == "follow":
        follow = open_follow(settings, bridge, pmap)
        state = follow.rendered_state
        return RunSource(follow, follow.sim.scenario.camera,
                         truth_of=lambda f: getattr(state(f.index), "position_ned_m", None))
    source = await open_source(settings.source, open_sim)
    sim = simulator_of(source)
    if c.kind not in RECORDED_KINDS:
        return RunSource(source, sim.scenario.camera if sim is not None else settings.camera)
    clocked = OnCompanionClock(source)
    camera = recording_camera(settings.camera, source, c.spec)
    if not isinstance(source, RecordedStreamSource):
        return RunSource(clocked, camera)
    truth = RecordedTruth(clocked, source, pmap.origin)
    return RunSource(clocked, camera, TruthAttitude(truth) if truth_attitude else None,
                     (lambda f: truth.position(f.t_us)) if truth else None)


async def _run(settings: Settings, seconds: float | None, fly_square: bool = False,
               truth_attitude: bool = False) -> CompanionApp:
    pmap = load_practical_map(settings)
    bridge = bridge_for(settings)
    run_source = await open_run_source(settings, bridge, pmap, truth_attitude)
    source = run_source.source
    pmap = with_sim_references(pmap, source)

    def processor(sensors: SensorHistory) -> Perception | PerceptionWrapper:
        perception = perception_for(settings, run_source.camera, pmap, sensors)
        if run_source.truth_of is not None:
            return TruthTagger(perception, run_source.truth_of)
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
        app = await fly(settings, source, bridge, processor, pmap, seconds=seconds,
                        prefix="run", on_start=start_flying if fly_square else None,
                        attitude=run_source.attitude)
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
    """Fly until stopped: 0 at the end of a finite source or ``--seconds``, 128 + N when
    signal N stopped it (the CLI's root), 1 when the frame source failed for good (so
    systemd's ``Restart=on-failure`` restarts it), 2 for what :func:`preflight` refuses."""
    preflight(settings)
    app = asyncio.run(_run(settings, args.seconds, getattr(args, "fly", False),
                           getattr(args, "truth_attitude", False)))
    c = app.counters
    line, none_sent = outcome_lines(getattr(app.sink, "results", {}))
    log.info("stopped: %d frames, %s, %d dropped frames", c.frames, line, app.dropped_frames)
    if none_sent is not None:
        log.warning("%s", none_sent)
    if app.blocker is not None:
        log.warning("no fix could come: %s: %s", app.blocker.cause, app.blocker.detail)
    if c.worker_errors:  # a bug, logged with its traceback: not a clean stop
        print("companion: frame processing failed (see the log above)", file=sys.stderr)
        return EXIT_FAILURE
    if app.source_failure is not None:
        raise SourceError(f"frame source failed: {app.source_failure}")
    return EXIT_OK
