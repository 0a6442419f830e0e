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
  the last one and delivered once it is done.  From the first frame the companion's clock
  (its frames' stamps, its bridge, the arrival of the autopilot's messages) *is* the
  recording's: ``T(r) = T0 + r``, stepped, as the fake's, so that the perception sees the
  recording's time between frames however fast or loaded the machine is (before, frames
  were stamped at their delivery: a loaded machine's longer steps changed the replay's
  figures).  The fake's clock is stepped to the frame's ``r``, it sends what is due (the
  recorded telemetry up to ``r``), the replay waits for those bytes to arrive, and the
  frame is delivered stamped ``T(r)``.  The latency is the processing's own: the frame's
  stamp against its stamp plus the real time since its delivery.  After the last frame
  the clock runs on in real time (the flight's end waits on it).

The attitude: a version-2 stream's recorded ATTITUDE, replayed by the fake
(:mod:`mavlink_bridge.fake_replay`); without telemetry, ``truth_pose.csv`` plus an
autopilot's stated error (:class:`companion.recorded.TruthAttitude`), said in one line.
Scores: :mod:`companion.replay_score`.
"""

from __future__ import annotations

import asyncio
import bisect
import dataclasses
import itertools
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
from companion.sources.base import EndOfStream, Frame, monotonic_us
from companion.sources.files import RecordedStreamSource
from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.endpoint import Connection
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.fake_replay import RecordedMessage, TelemetryReplay
from mavlink_bridge.vehicle import TruthFn, VehicleState

log = logging.getLogger(__name__)

#: How long the replay waits for the companion to ask the fake for its streams.
READY_S = 5.0
#: ``--fast`` steps the fake autopilot's clock by its own loop period (10 ms).
TICK_US = 10_000
#: How long ``--fast`` lets the companion take in the telemetry of a step once its bytes
#: have arrived, before the frame.
SETTLE_S = 0.002
#: How long ``--fast`` waits for a step's telemetry to arrive at most (a datagram lost on
#: loopback: the frame goes on without it, and the wait is logged), looking this often.
ARRIVAL_S = 1.0
ARRIVAL_POLL_S = 0.0002
#: ``--fast``'s pre-roll: a HEARTBEAT every this many 10 ms polls (the link comes up on it)
BEAT_POLLS = 10


class ReplayClock:
    """The recording's time on the companion's clock (module doc).

    ``fake_ns`` is the fake autopilot's clock, from the fake's start (its flight time 0,
    ``t0_ns``); the pre-roll lasts until :meth:`start` at the first frame (the link comes
    up, the companion asks for its streams and sets the origin) and the recording's time 0
    is then the fake's flight time :attr:`preroll_s`: the fake flies and replays
    ``recording_s(flight time)``.  In real time both clocks are the machine's; in
    ``--fast`` they are the recording's as stepped (the pre-roll takes none of it), and
    ``companion_ns`` is the companion's bridge's."""

    def __init__(self, fast: bool) -> None:
        self.fast = fast
        self.t0_ns = time.monotonic_ns()
        self.started_ns: int | None = None
        self.recorded_us = 0
        #: ``--fast``: when the last frame was delivered (None while stepping), and when the
        #: stream ended (the clock runs on in real time from then)
        self.delivered_ns: int | None = None
        self.ended_ns: int | None = None
        self._end_extra_ns = 0
        #: the real time a frame's processing adds to ``companion_ns`` at most: less than
        #: the next step (a 10 ms tick, or the stream's shortest frame interval)
        self.processing_cap_ns = TICK_US * 1000 - 1000
        #: called with :attr:`preroll_s` at :meth:`start`
        self.on_start: list[Callable[[float], None]] = []

    @property
    def preroll_s(self) -> float:
        return 0.0 if self.started_ns is None else (self.started_ns - self.t0_ns) / 1e9

    @property
    def stepped(self) -> bool:
        """``--fast`` after the first frame: the clock is the recording's, stepped."""
        return self.fast and self.started_ns is not None

    def start(self) -> None:
        # --fast: the pre-roll took none of the recording's clock (it stood at t0_ns)
        self.started_ns = self.t0_ns if self.fast else time.monotonic_ns()
        for fn in self.on_start:
            fn(self.preroll_s)

    def end(self) -> None:
        """The stream has no more frames: ``--fast``'s clocks run on in real time."""
        if self.ended_ns is None:
            self._end_extra_ns = self._processing_ns()
            self.ended_ns = time.monotonic_ns()

    def _processing_ns(self) -> int:
        """The real time since the last frame's delivery, up to the next step
        (:attr:`processing_cap_ns`; 0 while stepping)."""
        if self.delivered_ns is None:
            return 0
        return min(time.monotonic_ns() - self.delivered_ns, self.processing_cap_ns)

    def fake_ns(self) -> int:
        """The fake's clock: real time; in ``--fast`` the recording's time as stepped
        (:attr:`recorded_us`; module doc), standing at :attr:`t0_ns` through the pre-roll,
        so that the fake's estimator (its noise drawn per step) starts the recording in
        the same state however long the link took to come up."""
        if not self.fast:
            return time.monotonic_ns()
        ran_on = 0 if self.ended_ns is None else time.monotonic_ns() - self.ended_ns
        return self.t0_ns + self.recorded_us * 1000 + ran_on

    def companion_ns(self) -> int:
        """The companion's bridge's clock: the fake's, and in ``--fast`` while a frame is
        processed also the real time since its delivery, up to the next step: a fix's age
        is its processing's, and the clock never steps back."""
        if not self.fast:
            return time.monotonic_ns()
        extra = self._processing_ns() if self.ended_ns is None else self._end_extra_ns
        return self.fake_ns() + extra

    def recording_s(self, flight_s: float) -> float:
        """The recording's time at the fake's flight time (0 during the pre-roll)."""
        return 0.0 if self.started_ns is None else max(flight_s - self.preroll_s, 0.0)

    def companion_us(self, recorded_us: int) -> int:
        """When a frame recorded at ``recorded_us`` is due (real time), or is stamped
        (``--fast``)."""
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
        #: ``--fast``: the fake's HEARTBEAT, sent through the pre-roll (its clock stands)
        self.beat: Callable[[], None] | None = None
        #: True once the autopilot streams what the companion asked (waited for, up to
        #: :data:`READY_S`, before the first frame)
        self.ready: Callable[[], bool] = lambda: True
        self.first_us: int | None = None
        #: ``--fast``: the two ends of the loopback (the fake's, the companion's), whose
        #: bytes in flight are waited for: a step's telemetry is in before its frame, and a
        #: frame's fix reached the fake before the next step (UDP: bytes written, read)
        self.ends: tuple[Callable[[], Connection | None], Callable[[], Connection | None]] = (
            lambda: None, lambda: None)
        self.delivered = self.finished = self.settled = 0
        self._done = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        times = [e.t_us for e in stream.entries]
        shortest = min((b - a for a, b in itertools.pairwise(times) if b > a),
                       default=TICK_US)
        clock.processing_cap_ns = min(TICK_US, shortest) * 1000 - 1000
        period = 1.0 / stream.meta.fps if stream.meta.fps > 0 else 0.0
        self.seconds = (times[-1] - times[0]) / 1e6 + period if times else 0.0

    async def _wait_ready(self) -> None:
        for i in range(round(READY_S / 0.01)):
            if self.ready():
                return
            if self.beat is not None and i % BEAT_POLLS == 0:
                self.beat()
            await asyncio.sleep(0.01)
        log.warning("replay: the companion did not ask the fake autopilot for its streams "
                    "within %g s: starting anyway", READY_S)

    async def _arrival(self) -> None:
        """``--fast``: until every byte either end wrote has been read by the other (or
        :data:`ARRIVAL_S` passed), then :data:`SETTLE_S` for the readers to take it in."""
        for _ in range(round(ARRIVAL_S / ARRIVAL_POLL_S)):
            if self._in_flight() <= 0:
                break
            await asyncio.sleep(ARRIVAL_POLL_S)
        else:
            log.debug("replay: %d bytes still in flight on the loopback after %g s",
                      self._in_flight(), ARRIVAL_S)
        await asyncio.sleep(SETTLE_S)

    def _in_flight(self) -> int:
        fake, ours = (end() for end in self.ends)
        if fake is None or ours is None:
            return 0
        return (fake.bytes_written - ours.bytes_read) + (ours.bytes_written - fake.bytes_read)

    def now_us(self) -> int:
        """The companion's clock for the latency: real time, and in ``--fast`` the last
        frame's stamp plus the real time since its delivery (the processing's own)."""
        if not self.clock.stepped or self.last_us is None:
            return monotonic_us()
        since = self.clock.delivered_ns
        return self.last_us + (0 if since is None else (time.monotonic_ns() - since) // 1000)

    def _step_to(self, r_us: int) -> None:
        """``--fast``: the fake's clock to ``r_us`` in its own 10 ms ticks (its streams are
        scheduled as in continuous time, not once per frame)."""
        self.clock.delivered_ns = None
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
        try:
            frame = await self.stream.recv()
        except EndOfStream:
            self.clock.end()
            raise
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
            await self._arrival()  # the last frame's fix at the fake first
            self._step_to(r_us)
            await self._arrival()
            t_us = self.clock.companion_us(r_us)
            self.clock.delivered_ns = time.monotonic_ns()
        else:
            t_us = self.clock.companion_us(r_us)
            await asyncio.sleep(max(0.0, (t_us - monotonic_us()) / 1e6))
        t_us = max(t_us, (self.last_us or 0) + 1)
        self.remember(t_us, frame.index, frame.t_us)
        self.delivered += 1
        return dataclasses.replace(frame, t_us=t_us)


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


def _attitude(settings: Settings, truth: RecordedTruth, telemetry: TelemetryReplay | None,
              seed: int = 0) -> tuple[Settings, TruthAttitude | None, str]:
    """Where the solver's attitude comes from (said in one line), and the settings that
    state its noise to the solver; ``seed``: the simulated error's, without telemetry."""
    uses_telemetry = telemetry is not None and telemetry.covers("ATTITUDE")
    attitude = None if uses_telemetry or not truth else TruthAttitude(truth, seed=seed)
    if attitude is not None:
        from companion.demo import with_fake_attitude_sigmas

        seconds = max((t for t, _ in truth.poses.values()), default=0) / 1e6
        # the solver is told that noise, drift over the recording included
        settings = with_fake_attitude_sigmas(settings, attitude.config, seconds)
    said = ("the recording's ATTITUDE (telemetry.csv), replayed by the fake autopilot"
            if uses_telemetry else "truth_pose.csv with an autopilot's stated noise "
            f"(no recorded telemetry; error seed {seed})" if attitude is not None
            else "the fake autopilot's")
    log.warning("replay: attitude from %s", said)
    return settings, attitude, said


def _fake(settings: Settings, clock: ReplayClock, source: ReplaySource, truth: RecordedTruth,
          telemetry: TelemetryReplay | None) -> FakeAutopilot:
    """The fake autopilot flying the recording on its time, replaying its telemetry."""
    flight = recorded_flight(truth.poses) or (telemetry.trajectory() if telemetry else None)
    # one clock for the fake and the companion (module doc): its jitter correction as
    # ArduPilot's
    fake = FakeAutopilot(FakeAutopilotConfig(profile=settings.vehicle.profile,
                                             endpoint="udpin:127.0.0.1:0"),
                         truth=None if flight is None else
                         lambda t: flight(clock.recording_s(t)),
                         clock_ns=clock.fake_ns, replay=telemetry)
    clock.t0_ns = fake.start_ns
    if telemetry is not None:
        clock.on_start.append(telemetry.start)
    source.step = fake.tick
    # the streams asked and the EKF origin set: what the fake sends from the first frame on
    # does not depend on how long the link took to come up
    source.ready = lambda: "ATTITUDE" in fake.streams.periods and fake.origin is not None
    return fake


async def run_replay(settings: Settings, folder: Path, fast: bool = False,
                     attitude_seed: int = 0) -> dict[str, Any]:
    """Replay ``folder`` through the whole companion; returns the summary
    (:func:`companion.replay_score.replay_summary`).  ``attitude_seed``: the simulated
    autopilot error's seed for a stream without recorded telemetry."""
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
    settings, attitude, said = _attitude(settings, truth, telemetry, attitude_seed)
    detector_for(settings)  # loaded before the clock starts
    fake = _fake(settings, clock, source, truth, telemetry)
    camera = stream.meta.camera
    await fake.start()
    cpu0, wall0 = os.times(), time.monotonic()
    try:
        o = pmap.origin
        # --fast: the bridge on the recording's clock, as the frames and the fake (module doc)
        bridge = bridge_for(settings, clock.companion_ns if fast else None,
                            endpoint=f"udpout:127.0.0.1:{fake.local_port}",
                            origin_lat_deg=o.lat_deg, origin_lon_deg=o.lon_deg,
                            origin_alt_m=o.alt_m, set_origin=True)
        if fast:  # bridge_for refuses MAVSDK on a clock of ours
            assert isinstance(bridge, PymavlinkBridge)
            link = bridge.link
            source.ends = (lambda: fake.connection, lambda: link.connection)
            source.beat = fake.send_heartbeat
        flight = CompanionFlight(settings, source, bridge, pmap, camera, attitude=attitude,
                                 prefix="replay", clock_us=source.now_us if fast else None)
        scorer = ReplayScorer(truth, camera, pmap.landmarks, flight.sensors)
        flight.observe(scorer, source)  # the source last: the scoring is done when it hears
        app = await flight.run()
    finally:
        cpu1, wall1 = os.times(), time.monotonic()
        await fake.stop()
    busy = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / max(wall1 - wall0, 1e-9)
    visible = visible_counts(truth, camera, pmap.landmarks)
    return replay_summary(app, fake, bridge, scorer, source, busy, visible,
                          {"attitude": said, "mode": "fast" if fast else "real time",
                           "stream": str(folder)})
