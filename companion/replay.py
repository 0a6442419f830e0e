"""``companion replay``: the whole companion on a recorded stream, on one clock.

The recording's time ``r`` (0 at its first frame) is mapped onto the companion's
monotonic clock, and everything runs on that mapping: a frame recorded at ``r`` is stamped
``T(r)`` (so the bridge's fix-age gate, the attitude lookup and the latency all see one
time), and the fake autopilot (in-process, on UDP loopback, as in ``companion demo``) flies
on the recording's time: its flight time *is* ``r``, so the telemetry it sends and the
flight it judges fixes against are the recording's at the frame's moment.

* real time (default): ``T(r) = T0 + r``; a frame is delivered at ``T(r)``; when the
  processing falls behind, frames are dropped as from a live camera.
* ``--fast``: no frame is dropped; the next frame is decoded while the worker processes
  the last one and delivered once it is done.  The fake's clock is stepped to the frame's
  ``r``, it sends what is due (the recorded telemetry up to ``r``) and the frame is then
  stamped with the companion's clock ``T`` at its delivery: ``r -> T`` is monotonic,
  piecewise, and the same for the gate, the attitude lookup and the latency.

The attitude: a version-2 stream's recorded ATTITUDE, replayed by the fake
(:mod:`mavlink_bridge.fake_replay`); without telemetry, ``truth_pose.csv`` plus an
autopilot's stated error (:class:`companion.recorded.TruthAttitude`), said in one line.
Scores: :mod:`companion.replay_score`.
"""

from __future__ import annotations

import asyncio
import bisect
import dataclasses
import logging
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.app import Frame as PipelineFrame
from companion.app import FrameResult, ResultObserver
from companion.core.stream_format import TruthPose
from companion.core.stream_io import read_telemetry
from companion.errors import InputError
from companion.flightmap import load_practical_map
from companion.recorded import OnCompanionClock, RecordedTruth, TruthAttitude
from companion.replay_score import ReplayScorer, replay_summary, visible_counts
from companion.runtime import CompanionFlight, bridge_for, detector_for
from companion.settings import Settings
from companion.sources.base import Frame, monotonic_us
from companion.sources.files import RecordedStreamSource
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.fake_replay import RecordedMessage, TelemetryReplay
from mavlink_bridge.vehicle import TruthFn, VehicleState

log = logging.getLogger(__name__)

#: How long the replay waits for the companion to ask the fake for its streams.
READY_S = 5.0
#: ``--fast`` steps the fake autopilot's clock by its own loop period (10 ms).
TICK_US = 10_000
#: How long ``--fast`` lets the loopback deliver the telemetry of a step before the frame.
SETTLE_S = 0.002


class ReplayClock:
    """The recording's time on the companion's clock (module doc).

    ``fake_ns`` is the fake autopilot's clock.  It runs in real time from the fake's start
    (its flight time 0, ``t0_ns``) until :meth:`start` at the first frame -- the pre-roll,
    in which the link comes up and the companion asks for its streams -- and the
    recording's time 0 is then the fake's flight time :attr:`preroll_s`: the fake flies
    and replays ``recording_s(flight time)``."""

    def __init__(self, fast: bool) -> None:
        self.fast = fast
        self.t0_ns = time.monotonic_ns()
        self.started_ns: int | None = None
        self.recorded_us = 0
        #: called with :attr:`preroll_s` at :meth:`start`
        self.on_start: list[Callable[[float], None]] = []

    @property
    def preroll_s(self) -> float:
        return 0.0 if self.started_ns is None else (self.started_ns - self.t0_ns) / 1e9

    def start(self) -> None:
        self.started_ns = time.monotonic_ns()
        for fn in self.on_start:
            fn(self.preroll_s)

    def fake_ns(self) -> int:
        if self.fast and self.started_ns is not None:
            return self.started_ns + self.recorded_us * 1000
        return time.monotonic_ns()

    def recording_s(self, flight_s: float) -> float:
        """The recording's time at the fake's flight time (0 during the pre-roll)."""
        return 0.0 if self.started_ns is None else max(flight_s - self.preroll_s, 0.0)

    def companion_us(self, recorded_us: int) -> int:
        """Real time: when a frame recorded at ``recorded_us`` is due."""
        return (self.started_ns or time.monotonic_ns()) // 1000 + recorded_us


class ReplaySource(OnCompanionClock, ResultObserver):
    """A recorded stream delivered on a :class:`ReplayClock` (module doc).  It also
    observes the flight's results: ``--fast`` delivers the next frame only once the last
    one's ``on_result`` and ``on_after_work`` reached it -- observed last, so the
    observers before it (the scoring) are done with that frame too."""

    def __init__(self, stream: RecordedStreamSource, clock: ReplayClock) -> None:
        super().__init__(stream)
        self.stream = stream
        self.clock = clock
        #: called after the clock stepped (the fake sends what is due)
        self.step: Callable[[], None] | None = None
        #: True once the autopilot streams what the companion asked (waited for, up to
        #: :data:`READY_S`, before the first frame)
        self.ready: Callable[[], bool] = lambda: True
        self.first_us: int | None = None
        self.delivered = self.finished = self.settled = 0
        self._done = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        times = [e.t_us for e in stream.entries]
        period = 1.0 / stream.meta.fps if stream.meta.fps > 0 else 0.0
        self.seconds = (times[-1] - times[0]) / 1e6 + period if times else 0.0

    async def _wait_ready(self) -> None:
        for _ in range(round(READY_S / 0.01)):
            if self.ready():
                return
            await asyncio.sleep(0.01)
        log.warning("replay: the companion did not ask the fake autopilot for its streams "
                    "within %g s: starting anyway", READY_S)

    def _step_to(self, r_us: int) -> None:
        """``--fast``: the fake's clock to ``r_us`` in its own 10 ms ticks (its streams are
        scheduled as in continuous time, not once per frame)."""
        for t_us in [*range(self.clock.recorded_us + TICK_US, r_us, TICK_US), r_us]:
            self.clock.recorded_us = t_us
            if self.step is not None:
                self.step()

    def on_result(self, frame: PipelineFrame, result: FrameResult) -> None:
        """The worker thread finished a frame (and the observers before this one)."""
        self.finished += 1
        self._wake()

    def on_after_work(self, frame: PipelineFrame) -> None:
        """The background lane's thread finished a frame's after-work (acquisition:
        ``--fast`` waits for it too, so that a replay's result depends on the stream and
        the settings alone, not on how the threads happened to run)."""
        self.settled += 1
        self._wake()

    def _wake(self) -> None:
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._done.set)

    async def recv(self) -> Frame:
        self._loop = asyncio.get_running_loop()
        frame = await self.stream.recv()
        if self.first_us is None:
            self.first_us = frame.t_us
            await self._wait_ready()
            self.clock.start()
        r_us = frame.t_us - self.first_us
        if self.clock.fast:
            # the worker, or the after-work's lane, is still on the last one
            while min(self.finished, self.settled) < self.delivered:
                self._done.clear()
                await self._done.wait()
            self._step_to(r_us)
            await asyncio.sleep(SETTLE_S)
            t_us = monotonic_us()
        else:
            t_us = self.clock.companion_us(r_us)
            await asyncio.sleep(max(0.0, (t_us - monotonic_us()) / 1e6))
        t_us = max(t_us, (self.last_us or 0) + 1)
        self.remember(t_us, frame.index, frame.t_us)
        self.delivered += 1
        return Frame(frame.index, t_us, frame.image, frame.camera_id)


async def _heartbeats(fake: FakeAutopilot) -> None:
    """``--fast``: the fake's HEARTBEAT at 1 Hz of the companion's clock as well.  Its
    streams follow the recording's stepped time, but a link's liveness is judged on the
    companion's clock (``mavlink.link_timeout_s``): a processing slower than a third of
    real time would otherwise let the link time out (``no_link`` refusals, seen at load
    average 18)."""
    while True:
        await asyncio.sleep(1.0)
        fake.send_heartbeat()


def recorded_flight(poses: dict[int, tuple[int, TruthPose]]) -> TruthFn | None:
    """``truth_pose.csv`` as the fake autopilot's flight (interpolated position, velocity
    by differences, the nearest earlier attitude), on the recording's time from its first
    frame; None without poses."""
    rows = sorted(poses.values(), key=lambda r: r[0])
    if not rows:
        return None
    t0 = rows[0][0]
    times = [(t - t0) / 1e6 for t, _ in rows]
    pos = [(p.north_m, p.east_m, p.down_m) for _, p in rows]

    def truth(t: float) -> VehicleState:
        i = min(max(bisect.bisect_right(times, t) - 1, 0), len(rows) - 1)
        j = min(i + 1, len(rows) - 1)
        dt = times[j] - times[i]
        f = 0.0 if dt <= 0 else min(max((t - times[i]) / dt, 0.0), 1.0)
        p = tuple(a + f * (b - a) for a, b in zip(pos[i], pos[j], strict=True))
        v = tuple(0.0 if dt <= 0 else (b - a) / dt for a, b in zip(pos[i], pos[j], strict=True))
        q = rows[i][1]
        rng = max(-p[2], 0.0) / max(math.cos(q.roll_rad) * math.cos(q.pitch_rad), 0.1)
        return VehicleState(t, p, v, (q.roll_rad, q.pitch_rad, q.yaw_rad), rng)  # type: ignore[arg-type]

    return truth


def replay_settings(settings: Settings, stream: RecordedStreamSource) -> Settings:
    """The EKF origin is the stream's ``[origin]``; the map, unless ``landmarks.map_path``
    is set, the stream's own ``landmarks.geojson`` when it has one (``companion synth``)."""
    mav, lms = settings.mavlink, settings.landmarks
    o = stream.meta.origin
    if o is not None:
        mav = dataclasses.replace(mav, origin_lat_deg=o.lat, origin_lon_deg=o.lon,
                                  origin_alt_m=o.alt_m)
    own = stream.folder / "landmarks.geojson"
    if not lms.map_path and own.is_file():
        log.info("replay: the stream's own map %s", own)
        lms = dataclasses.replace(lms, map_path=str(own))
    return dataclasses.replace(settings, mavlink=mav, landmarks=lms)


def telemetry_of(folder: Path) -> TelemetryReplay | None:
    """The stream's recorded telemetry (format version 2) on its time from the first
    frame, or None when it has none."""
    rows = read_telemetry(folder)
    if not rows:
        return None
    stream = RecordedStreamSource(folder, realtime=False)
    first = min((e.t_us for e in stream.entries), default=0)
    stream.close()
    return TelemetryReplay([RecordedMessage((t - first) / 1e6, name, fields)
                            for t, name, fields in rows])


def _attitude(settings: Settings, truth: RecordedTruth, telemetry: TelemetryReplay | None
              ) -> tuple[Settings, TruthAttitude | None, str]:
    """Where the solver's attitude comes from (said in one line), and the settings that
    state its noise to the solver."""
    uses_telemetry = telemetry is not None and telemetry.covers("ATTITUDE")
    attitude = None if uses_telemetry or not truth else TruthAttitude(truth)
    if attitude is not None:
        from companion.demo import with_fake_attitude_sigmas

        seconds = max((t for t, _ in truth.poses.values()), default=0) / 1e6
        # the solver is told that noise, drift over the recording included
        settings = with_fake_attitude_sigmas(settings, attitude.config, seconds)
    said = ("the recording's ATTITUDE (telemetry.csv), replayed by the fake autopilot"
            if uses_telemetry else "truth_pose.csv with an autopilot's stated noise "
            "(no recorded telemetry)" if attitude is not None else "the fake autopilot's")
    log.warning("replay: attitude from %s", said)
    return settings, attitude, said


def _fake(settings: Settings, clock: ReplayClock, source: ReplaySource, truth: RecordedTruth,
          telemetry: TelemetryReplay | None) -> FakeAutopilot:
    """The fake autopilot flying the recording on its time, replaying its telemetry."""
    flight = recorded_flight(truth.poses) or (telemetry.trajectory() if telemetry else None)
    # --fast: the fake's clock is the recording's and the stamps the companion's, two bases
    # that drift apart; ArduPilot's jitter correction would read that drift as link lag
    fake = FakeAutopilot(FakeAutopilotConfig(profile=settings.vehicle.profile,
                                             endpoint="udpin:127.0.0.1:0",
                                             jitter_correction=not clock.fast),
                         truth=None if flight is None else
                         lambda t: flight(clock.recording_s(t)),
                         clock_ns=clock.fake_ns, replay=telemetry)
    clock.t0_ns = fake.start_ns
    if telemetry is not None:
        clock.on_start.append(telemetry.start)
    source.step = fake.tick
    source.ready = lambda: "ATTITUDE" in fake.streams.periods
    return fake


async def run_replay(settings: Settings, folder: Path, fast: bool = False) -> dict[str, Any]:
    """Replay ``folder`` through the whole companion; returns the summary
    (:func:`companion.replay_score.replay_summary`)."""
    stream = RecordedStreamSource(folder, realtime=False)
    settings = replay_settings(settings, stream)
    telemetry = telemetry_of(folder)
    clock = ReplayClock(fast)
    source = ReplaySource(stream, clock)
    pmap = load_practical_map(settings)
    truth = RecordedTruth(source, stream, pmap.origin)
    if not truth and telemetry is None:
        raise InputError(f"{folder}: neither truth_pose.csv nor telemetry.csv: nothing to "
                         "take the attitude from or to score against (docs/replay.md)")
    settings, attitude, said = _attitude(settings, truth, telemetry)
    detector_for(settings)  # loaded before the clock starts
    fake = _fake(settings, clock, source, truth, telemetry)
    camera = stream.meta.camera
    await fake.start()
    beats = asyncio.create_task(_heartbeats(fake) if fast else asyncio.sleep(0))
    cpu0, wall0 = os.times(), time.monotonic()
    try:
        o = pmap.origin
        bridge = bridge_for(settings, endpoint=f"udpout:127.0.0.1:{fake.local_port}",
                            origin_lat_deg=o.lat_deg, origin_lon_deg=o.lon_deg,
                            origin_alt_m=o.alt_m, set_origin=True)
        flight = CompanionFlight(settings, source, bridge, pmap, camera, attitude=attitude,
                                 prefix="replay")
        if fast:  # the fake's clock is stepped: its time_boot_ms does not run with ours
            flight.sensors.boot_clock = None
        scorer = ReplayScorer(truth, camera, pmap.landmarks, flight.sensors)
        flight.observe(scorer, source)  # the source last: the scoring is done when it hears
        app = await flight.run()
    finally:
        cpu1, wall1 = os.times(), time.monotonic()
        beats.cancel()
        await asyncio.gather(beats, return_exceptions=True)
        await fake.stop()
    busy = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / max(wall1 - wall0, 1e-9)
    visible = visible_counts(truth, camera, pmap.landmarks)
    return replay_summary(app, fake, bridge, scorer, source, busy, visible,
                          {"attitude": said, "mode": "fast" if fast else "real time",
                           "stream": str(folder)})
