"""The SITL harness: the whole companion against the fake autopilot in the simulated world.

A :class:`Flight` assembles what ``companion demo`` assembles -- the simulator, the
real-time simulated camera, the scripted :class:`~mavlink_bridge.fake_autopilot.FakeAutopilot`
on UDP loopback flying the camera's trajectory, the configured bridge, and
:class:`companion.runtime.CompanionFlight` (which builds the real
:class:`~companion.app.CompanionApp`, observed by a :class:`FrameRecorder`) -- and runs a
scenario *script* beside it.  Everything the test asserts on is recorded:

* :attr:`SitlAutopilot.arrivals` -- every vision message the autopilot received, with its
  arrival on the flight clock, its age (arrival minus time stamp) and the autopilot's verdict;
* :attr:`Flight.frames` -- every frame the companion processed, with the simulator's truth
  (which landmarks were in view and how much of each was occluded) and the fix, if any;
* :attr:`Flight.stimuli` -- every fault the script injected, with its flight time, so a test
  can prove its stimulus happened ("otherwise we have not actually tested anything").

Clocks: the flight clock is the fake autopilot's (``flight_s``, 0 = truth time 0 = frame 0
of the scenario); frame times are scenario times from the frames' own stamps, so they stay
right when a loaded machine makes the camera skip frames.  The MAVLink stack runs on the
monotonic clock, so flights run in real time: scenarios are kept to 10-20 s.

:func:`wait_until` is ArduPilot autotest's ``WaitAndMaintain``: a condition must become true
within a timeout and then stay true for a hold time, or the test fails naming what it waited for.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.app import CompanionApp, FrameResult, ResultObserver
from companion.demo import map_landmarks, nees_3d, with_fake_attitude_sigmas
from companion.flightlog import FlightLog, read_flight_log
from companion.landmarks.geodesy import LocalFrame
from companion.runtime import CompanionFlight, PracticalMap, bridge_for
from companion.settings import SIM_LAYERS, Settings, load_settings
from companion.sim.effects import EffectSpec
from companion.sim.scenario import ScenarioConfig, load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource
from companion.sources.base import Frame
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.fake_drift import AttitudeErrorConfig
from mavlink_bridge.fake_rules import VisionRecord
from tracker.pose.types import PoseFix

POLL_S = 0.02
# A fix is stale when it reaches the autopilot older than ``mavlink.max_fix_age_ms`` (the
# bridge never sends one older) plus this: the loopback and event-loop delay before the fake
# autopilot (same process) reads it, up to ~200 ms on a loaded 2-core machine.  A fix held
# over an outage is older by the outage (>= 1 s), far beyond it.
ARRIVAL_SLACK_MS = 250.0
# Camera rate of SITL flights: half the scenarios' 30 fps, so the whole pipeline keeps up on
# a loaded 2-core CI machine (at 30 fps there the camera skips most frames and tracking,
# not the property under test, decides the outcome).  Benchmarks measure the 30 fps case.
SITL_FPS = 15.0


# ------------------------------------------------------------------ the fake, recorded


@dataclass(frozen=True)
class Arrival:
    """One vision message at the autopilot: when (flight clock), how old, and its verdict."""

    flight_s: float
    age_ms: float  # arrival minus the message's time stamp (one monotonic clock)
    stamp_s: float  # the message's time stamp on the flight clock (= the frame's scenario time)
    accepted: bool
    reason: str
    position_ned_m: tuple[float, float, float]


class SitlAutopilot(FakeAutopilot):
    """The fake autopilot, also recording each vision message on the flight clock."""

    def __init__(self, config: FakeAutopilotConfig, **kwargs: Any) -> None:
        super().__init__(config, **kwargs)
        self.arrivals: list[Arrival] = []

    def _on_vision(self, name: str, msg: Any) -> None:
        super()._on_vision(name, msg)
        rec: VisionRecord = self.vision[-1]
        age_ms = (self.clock_ns() / 1000 - rec.time_usec) / 1000
        stamp_s = (rec.time_usec - self.start_ns / 1000) / 1e6
        self.arrivals.append(Arrival(self.flight_s(), age_ms, stamp_s, rec.accepted, rec.reason,
                                     rec.position_ned_m))

    def inject_to_companion(self, data: bytes) -> None:
        """Bytes onto the link towards the companion, as if this autopilot sent them (the
        companion's UDP socket is connected to us: nothing else can reach it)."""
        assert self.connection is not None
        self.connection.write(data)

    def inject_received(self, data: bytes) -> None:
        """Bytes into this autopilot as if they came over its link."""
        self._rx(data)

    def accepted_times(self) -> list[float]:
        return [a.flight_s for a in self.arrivals if a.accepted]


# ------------------------------------------------------------------ camera faults


@dataclass
class CameraFaults:
    """Faults the script sets on the camera; times on the flight clock."""

    stall_until_s: float = -1.0
    corrupt_left: int = 0
    corrupt_kind: str = "noise"  # noise | black | truncated | wrong_size
    corrupted: list[int] = field(default_factory=list)  # frame indices
    stalled_s: float = 0.0


class FaultyCamera:
    """A :class:`SimCameraSource` with a stall and corrupt frames on demand."""

    def __init__(self, inner: SimCameraSource, clock_s: Callable[[], float]) -> None:
        self.inner = inner
        self.sim = inner.sim
        self.status = inner.status
        self.seconds = inner.seconds
        self.faults = CameraFaults()
        self._clock_s = clock_s
        self._rng = np.random.default_rng(7)

    def truth(self, index: int) -> Any:
        return self.inner.truth(index)

    def scenario_time_s(self, frame: Frame) -> float:
        return self.inner.scenario_time_s(frame)

    def close(self) -> None:
        self.inner.close()

    async def recv(self) -> Frame:
        wait = self.faults.stall_until_s - self._clock_s()
        if wait > 0:  # a stuck driver: nothing comes out, then the camera resumes
            self.faults.stalled_s += wait
            await asyncio.sleep(wait)
        frame = await self.inner.recv()
        if self.faults.corrupt_left <= 0:
            return frame
        self.faults.corrupt_left -= 1
        self.faults.corrupted.append(frame.index)
        return dataclasses.replace(frame, image=self._corrupt(frame.image))

    def _corrupt(self, image: np.ndarray) -> np.ndarray:
        kind = self.faults.corrupt_kind
        if kind == "black":
            return np.zeros_like(image)
        if kind == "truncated":  # a torn read: the bottom of the image never arrived
            out = image.copy()
            out[image.shape[0] // 3:] = 0
            return out
        if kind == "wrong_size":
            return np.ascontiguousarray(image[: image.shape[0] // 2, : image.shape[1] // 2])
        return self._rng.integers(0, 256, image.shape, dtype=np.uint8)


# ------------------------------------------------------------------ what was processed


@dataclass(frozen=True)
class FrameRecord:
    """One processed frame with the simulator's truth."""

    index: int
    t_s: float  # scenario time of the frame
    visible: dict[str, float]  # landmark -> share of its face in view and not occluded
    truth_ned_m: tuple[float, float, float]
    fix_ned_m: tuple[float, float, float] | None = None
    fix_sigma_m: tuple[float, float, float] | None = None
    fix_landmarks: tuple[str, ...] = ()
    fix_nees: float | None = None  # e^T P_pos^-1 e against the truth
    fix_solver: str = ""
    bad_frame: bool = False
    brightness: float = 0.0  # mean grey level of the image


class FrameRecorder(ResultObserver):
    """Observes the flight's results; records every frame against the truth."""

    def __init__(self, camera: FaultyCamera, out: list[FrameRecord]) -> None:
        self.camera = camera
        self.out = out

    def on_result(self, frame: Frame, result: FrameResult) -> None:
        t_s = self.camera.scenario_time_s(frame)
        truth = self.camera.truth(frame.index)
        visible = {} if truth is None else {
            b.landmark_id: float(b.in_view_frac) * (1.0 - float(b.occluded_frac))
            for b in truth.boxes}
        state = self.camera.sim.state_at(t_s)
        rec = FrameRecord(frame.index, t_s, visible,
                          tuple(float(v) for v in state.position_ned_m),  # type: ignore[arg-type]
                          bad_frame=result.bad_frame, brightness=float(frame.image.mean()))
        if isinstance(result.fix, PoseFix):
            n, e, d = (float(v) for v in result.fix.position_ned_m)
            rec = dataclasses.replace(rec, fix_ned_m=(n, e, d),
                                      fix_sigma_m=result.fix.position_sigma_m,
                                      fix_landmarks=tuple(result.fix.landmark_ids),
                                      fix_nees=nees_3d(result.fix, rec.truth_ned_m),
                                      fix_solver=result.fix.solver)
        self.out.append(rec)


# ------------------------------------------------------------------ the flight


Script = Callable[["Flight"], Awaitable[None]]


def sitl_settings(tmp: Path, *, profile: str = "ardupilot", monitor: bool = False,
                  deployment_prior: bool = False, stated_for_s: float = 60.0,
                  shipped: tuple[str, ...] = SIM_LAYERS,
                  **sections: dict[str, Any]) -> Settings:
    """The default configuration with the simulator's layer (``shipped=()``: the deployment
    defaults alone, what a user flies before measuring the camera), flight logs in ``tmp``,
    monitoring off unless asked, and ``section={key: value}`` overrides.  The attitude prior
    states the default fake autopilot's real attitude error over a flight of ``stated_for_s``
    (as ``companion demo`` does: 1 deg roll/pitch, 3.2 deg yaw with a minute's drift) unless
    ``deployment_prior``: then the configured default (2.5 deg / 5 deg, docs/decisions.md)."""
    s = load_settings(sets=[f"vehicle.profile={profile}"], shipped=shipped)
    if not deployment_prior:
        s = with_fake_attitude_sigmas(s, AttitudeErrorConfig(), stated_for_s)
    s = dataclasses.replace(s, flightlog=dataclasses.replace(s.flightlog, dir=str(tmp)),
                            monitor=dataclasses.replace(s.monitor, enabled=monitor))
    for name, values in sections.items():
        s = dataclasses.replace(s, **{name: dataclasses.replace(getattr(s, name), **values)})
    return s


def compress_effects(scenario: ScenarioConfig, factor: float) -> ScenarioConfig:
    """The scenario with every scripted effect ``factor`` times sooner and shorter."""
    effects = tuple(dataclasses.replace(e, start_s=e.start_s * factor,
                                        end_s=e.end_s * factor if e.end_s < 1e8 else e.end_s)
                    for e in scenario.effects)
    return dataclasses.replace(scenario, effects=effects)


@dataclass
class Flight:
    """One simulated flight of the whole companion (see module doc)."""

    scenario: str | ScenarioConfig
    seconds: float
    settings: Settings
    fps: float | None = SITL_FPS  # None: the scenario's
    autopilot: FakeAutopilotConfig = field(default_factory=FakeAutopilotConfig)
    bridge_overrides: dict[str, Any] = field(default_factory=dict)
    frames: list[FrameRecord] = field(default_factory=list)
    stimuli: list[tuple[float, str]] = field(default_factory=list)
    app: CompanionApp | None = None
    fake: SitlAutopilot = field(init=False)
    camera: FaultyCamera = field(init=False)
    bridge: VisionBridge = field(init=False)
    sim: Simulator = field(init=False)

    async def run(self, script: Script | None = None) -> Flight:
        """Fly to the end of the scenario, running ``script`` beside it; re-raise its failure."""
        sc = self.scenario if isinstance(self.scenario, ScenarioConfig) \
            else load_scenario(self.scenario)
        self.sim = Simulator(dataclasses.replace(sc, seconds=self.seconds,
                                                 fps=self.fps or sc.fps))
        landmarks, references = map_landmarks(self.sim)
        o = self.sim.scenario.origin
        pmap = PracticalMap(tuple(landmarks), references, LocalFrame(o.lat, o.lon, o.alt_m))
        cfg = dataclasses.replace(self.autopilot, profile=self.settings.vehicle.profile,
                                  endpoint="udpin:127.0.0.1:0")
        self.fake = SitlAutopilot(cfg, truth=self.sim.truth_fn)
        await self.fake.start()
        self.camera = FaultyCamera(
            SimCameraSource(self.sim, realtime=True, seconds=self.seconds,
                            t0_us=self.fake.start_ns // 1000), self.flight_s)
        self.bridge = bridge_for(self.settings, endpoint=f"udpout:127.0.0.1:{self.fake.local_port}",
                                 origin_lat_deg=o.lat, origin_lon_deg=o.lon,
                                 origin_alt_m=o.alt_m, set_origin=True, **self.bridge_overrides)

        flight = CompanionFlight(self.settings, self.camera, self.bridge, pmap,
                                 self.sim.scenario.camera, prefix="sitl")
        flight.observe(FrameRecorder(self.camera, self.frames))
        tasks: list[asyncio.Task[None]] = []

        def on_start(app: CompanionApp) -> None:
            self.app = app
            if script is not None:
                tasks.append(asyncio.create_task(self._script(script, app), name="sitl-script"))

        try:
            await flight.run(self.seconds + 5.0, on_start=on_start)
        finally:
            for t in tasks:
                t.cancel()
            outcomes = await asyncio.gather(*tasks, return_exceptions=True)
            await self.fake.stop()
        for outcome in outcomes:
            if isinstance(outcome, BaseException) and not isinstance(outcome,
                                                                      asyncio.CancelledError):
                raise outcome
        return self

    async def _script(self, script: Script, app: CompanionApp) -> None:
        try:
            await script(self)
        except BaseException:
            app.request_stop()  # a failed wait ends the flight at once
            raise

    # -- clocks and stimuli ------------------------------------------------------------

    def flight_s(self) -> float:
        """The flight clock: seconds since truth time 0 (the fake autopilot's start)."""
        return self.fake.flight_s()

    def mark(self, what: str) -> float:
        """Record that a stimulus was applied now; returns the flight time."""
        t = self.flight_s()
        self.stimuli.append((t, what))
        return t

    async def sleep_until(self, flight_s: float) -> None:
        await asyncio.sleep(max(0.0, flight_s - self.flight_s()))

    # -- results -----------------------------------------------------------------------

    def stale(self, since_s: float = -1.0) -> list[Arrival]:
        """Vision messages that arrived after ``since_s`` older than the bridge allows."""
        limit = self.settings.mavlink.max_fix_age_ms + ARRIVAL_SLACK_MS
        return [a for a in self.fake.arrivals if a.flight_s >= since_s and a.age_ms > limit]

    def fixes(self) -> list[FrameRecord]:
        return [f for f in self.frames if f.fix_ned_m is not None]

    def errors_m(self) -> list[float]:
        return [math.dist(f.fix_ned_m, f.truth_ned_m) for f in self.fixes()
                if f.fix_ned_m is not None]

    def invented(self, min_visible: float = 1e-6) -> list[FrameRecord]:
        """Fixes that used a landmark the truth says was entirely out of view or hidden."""
        return [f for f in self.fixes()
                if any(f.visible.get(lid, 0.0) < min_visible for lid in f.fix_landmarks)]

    def flight_log(self) -> FlightLog:
        """The flight log this flight wrote (the only one in ``flightlog.dir``)."""
        logs = sorted(Path(self.settings.flightlog.dir).glob("sitl-*.jsonl"))
        assert len(logs) == 1, f"expected one flight log, found {logs}"
        return read_flight_log(logs[0])

    def rmse_m(self) -> float:
        e = self.errors_m()
        return float(np.sqrt(np.mean(np.square(e)))) if e else math.inf


async def wait_until(flight: Flight, condition: Callable[[], bool], *, timeout_s: float,
                     hold_s: float = 0.0, what: str) -> float:
    """Wait (flight clock) until ``condition`` is true and stays true for ``hold_s``;
    returns the flight time it first became true.  Fails naming ``what`` on timeout."""
    deadline = flight.flight_s() + timeout_s
    since: float | None = None
    last = "never true"
    while True:
        now = flight.flight_s()
        if condition():
            since = now if since is None else since
            if now - since >= hold_s:
                return since
        else:
            if since is not None:
                last = f"true at {since:.2f} s but not held {hold_s:.1f} s"
            since = None
        if now > deadline + hold_s:
            raise AssertionError(f"{what}: not within {timeout_s:.1f} s ({last}), "
                                 f"flight time {now:.2f} s")
        await asyncio.sleep(POLL_S)


def first_at_or_after(times: Sequence[float], t: float) -> float | None:
    """The first time in increasing ``times`` that is >= ``t``."""
    return next((x for x in times if x >= t), None)


def max_gap_s(times: Sequence[float], start: float, end: float) -> float:
    """The longest interval without an event inside [start, end]."""
    inside = [start, *[x for x in times if start <= x <= end], end]
    return float(max(np.diff(inside))) if len(inside) > 1 else end - start


def effect(scenario: ScenarioConfig, kind: str) -> list[EffectSpec]:
    return [e for e in scenario.effects if e.kind == kind]


def monotonic_s() -> float:
    return time.monotonic()
