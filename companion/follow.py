"""The simulated camera that follows an autopilot simulator's *true* pose (closed loop).

ArduPilot SITL reports where the simulated vehicle truly is in SIM_STATE (and SIMSTATE,
which has no altitude); PX4 SITL in HIL_STATE_QUATERNION.  :class:`FollowCameraSource`
turns those into local NED about the configured EKF origin (:class:`LocalFrame`,
pymap3d), renders the scenario's world at the camera's frame rate from the pose
interpolated between telemetry samples, and stamps every frame on the companion's clock
with the time it shows.  The autopilot's own estimate (ATTITUDE, LOCAL_POSITION_NED) is
never used: that would close the loop on itself.

Truth missing at start -> a one-line :class:`SourceError` naming the message; truth that
stops arriving for ``stale_ms`` -> no frames (counted as stalls) until it comes back.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from companion.core.stream_format import FrameTruth
from companion.errors import SourceError
from companion.landmarks.geodesy import LocalFrame
from companion.sim.scenario import OriginConfig, ScenarioConfig
from companion.sim.simulator import Simulator
from companion.sim.source import OfSimulatedWorld
from companion.sim.trajectory import KinematicState
from companion.sources.base import Frame, ImageU8, SourceStatus
from companion.sources.config import FollowConfig
from mavlink_bridge.messages import euler_to_quaternion
from mavlink_bridge.telemetry import TRUTH_NAMES, SimTruth, Telemetry
from tracker.geometry import FloatArray, rpy_from_rotation

log = logging.getLogger(__name__)

#: Messages with a complete true pose, by vehicle profile (SIMSTATE lacks the altitude).
FULL_TRUTH = {"ardupilot": "SIM_STATE", "px4": "HIL_STATE_QUATERNION"}
MESSAGE_IDS = {"SIM_STATE": 108, "SIMSTATE": 164, "HIL_STATE_QUATERNION": 115}
MAV_CMD_SET_MESSAGE_INTERVAL = 511
SAMPLES_KEPT = 256
#: Samples read less than this apart (and under a quarter of the requested period) came in
#: one burst -- the companion's event loop was busy while they queued in the socket -- and
#: only the newest of a burst is kept (see add_sample).
BURST_NS = 5_000_000
TRUTH_KEPT = 256


class TelemetryFeed(Protocol):
    """What the source needs from the bridge (``VisionBridge`` satisfies it)."""

    def subscribe(self, *names: str) -> AsyncIterator[Telemetry]: ...
    def latest(self, name: str) -> Telemetry | None: ...
    @property
    def link_up(self) -> bool: ...


# --------------------------------------------------------------------- pure functions
@dataclass(frozen=True)
class TruthSample:
    """One true pose in local NED, stamped with the companion's receive time (ns)."""

    t_ns: int
    position_ned_m: FloatArray  # (3,)
    quaternion_wxyz: FloatArray  # (4,) unit, body FRD -> NED
    velocity_ned_m_s: FloatArray  # (3,)


def rotation_from_quaternion(q: FloatArray) -> FloatArray:
    """3x3 rotation of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q / np.linalg.norm(q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def slerp(q0: FloatArray, q1: FloatArray, s: float) -> FloatArray:
    """Spherical interpolation q0 -> q1 at ``s`` (s > 1 extrapolates along the same arc).

    q(s) = sin((1-s) th)/sin th q0 + sin(s th)/sin th q1, cos th = |q0 . q1| (short way)."""
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: linear is exact enough and avoids 0/0
        q = q0 + s * (q1 - q0)
        return np.asarray(q / np.linalg.norm(q), dtype=np.float64)
    th = math.acos(min(1.0, dot))
    q = (math.sin((1 - s) * th) * q0 + math.sin(s * th) * q1) / math.sin(th)
    return np.asarray(q / np.linalg.norm(q), dtype=np.float64)


def truth_sample(item: Telemetry, frame: LocalFrame) -> TruthSample | None:
    """A telemetry truth message as a local-NED sample; None when it lacks the altitude."""
    v = item.value
    if not isinstance(v, SimTruth) or v.alt_m is None:
        return None
    ned = frame.to_ned(v.lat_deg, v.lon_deg, v.alt_m)
    q = np.asarray(v.quaternion_wxyz if v.quaternion_wxyz is not None
                   else euler_to_quaternion(*v.attitude_rpy_rad), dtype=np.float64)
    vel = np.zeros(3) if v.velocity_ned_m_s is None else np.asarray(v.velocity_ned_m_s)
    return TruthSample(item.received_ns, np.asarray(ned, dtype=np.float64),
                       q / np.linalg.norm(q), vel.astype(np.float64))


def add_sample(samples: deque[TruthSample], sample: TruthSample,
               burst_ns: int = BURST_NS) -> None:
    """Append a sample stamped with its arrival, keeping only the newest of a burst.

    Arrival stamps are right when the companion reads the socket promptly.  After a stall
    several samples sent over the stall are read within microseconds: their stamps say
    "now" while their poses span the stall, and interpolating between two of them would
    stretch 20 ms of motion over a few microseconds.  The newest of the burst is the one
    whose stamp is right; the sample before the stall stays, and frames in between are
    interpolated across the stall from those two.
    """
    if samples and sample.t_ns - samples[-1].t_ns < burst_ns:
        samples[-1] = sample  # same burst: the newer value replaces the older
    else:
        samples.append(sample)


def state_at(samples: list[TruthSample] | deque[TruthSample], t_ns: int,
             max_extrapolation_ns: int, max_gap_ns: int | None = None) -> KinematicState | None:
    """The vehicle at ``t_ns`` from time-ordered samples, or None when it is not known.

    Between samples a and b: p = pa + s (pb - pa), q = slerp(qa, qb, s),
    s = (t - ta) / (tb - ta).  Past the newest sample the last pair is extrapolated for at
    most ``max_extrapolation_ns``; before the oldest the oldest is held.  Two samples more
    than ``max_gap_ns`` apart (the truth stopped in between) are not interpolated across.
    """
    if not samples:
        return None
    last = samples[-1]
    if t_ns - last.t_ns > max_extrapolation_ns:
        return None
    if len(samples) == 1 or t_ns <= samples[0].t_ns:
        a = b = samples[0] if t_ns <= samples[0].t_ns else last
    else:
        i = len(samples) - 1
        while i > 1 and samples[i - 1].t_ns >= t_ns:
            i -= 1
        a, b = samples[i - 1], samples[i]
    span = b.t_ns - a.t_ns
    if max_gap_ns is not None and span > max_gap_ns:
        return None
    s = (t_ns - a.t_ns) / span if span > 0 else 0.0
    pos = a.position_ned_m + s * (b.position_ned_m - a.position_ned_m)
    vel = a.velocity_ned_m_s + min(s, 1.0) * (b.velocity_ned_m_s - a.velocity_ned_m_s)
    rpy = rpy_from_rotation(rotation_from_quaternion(slerp(a.quaternion_wxyz,
                                                           b.quaternion_wxyz, s)))
    return KinematicState(t_ns / 1e9, (float(pos[0]), float(pos[1]), float(pos[2])),
                        (float(vel[0]), float(vel[1]), float(vel[2])), rpy)


def missing_truth_message(profile: str, heard: dict[str, int], link_up: bool,
                          timeout_s: float) -> str:
    """The one line that says which truth message never came (and why that matters)."""
    want = FULL_TRUTH.get(profile, "SIM_STATE")
    if not link_up:
        return (f"follow camera: no autopilot heard in {timeout_s:g} s, so no {want} "
                "(the simulator's true pose): is the simulator running on mavlink.endpoint?")
    if heard.get("SIMSTATE") and profile == "ardupilot":
        return (f"follow camera: SIMSTATE arrives but no SIM_STATE in {timeout_s:g} s: "
                "SIMSTATE carries no altitude; this ArduPilot does not send SIM_STATE "
                "(message 108) when asked (docs/sitl.md)")
    others = [n for n in TRUTH_NAMES if heard.get(n) and n != want]
    extra = f" ({', '.join(others)} came instead: set vehicle.profile)" if others else ""
    return (f"follow camera: the autopilot sends no {want} (the simulator's true pose) in "
            f"{timeout_s:g} s{extra}: a real vehicle or a simulator without it cannot be "
            "followed, and its own estimate would close the loop on itself")


# --------------------------------------------------------------------- the source
class FollowCameraSource(OfSimulatedWorld):
    """Frames of ``simulator``'s world seen from the pose an autopilot simulator reports.

    ``bridge`` gives the telemetry (``subscribe``/``latest``/``link_up``); ``origin`` is the
    configured EKF origin the truth is converted about; ``request`` (optional) sends a
    MAVLink message, used to ask for the truth stream with SET_MESSAGE_INTERVAL.
    """

    def __init__(self, simulator: Simulator, bridge: TelemetryFeed, origin: LocalFrame,
                 profile: str, config: FollowConfig | None = None, *,
                 request: Callable[..., None] | None = None,
                 clock_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.sim = simulator
        self.bridge = bridge
        self.origin = origin
        self.profile = profile
        self.config = config = config or FollowConfig()
        self.fps = config.fps or simulator.fps
        self.camera_id = simulator.scenario.camera_id
        self.status = SourceStatus()
        self.failure: SourceError | None = None
        self.heard: dict[str, int] = {}
        self._request = request
        self._asked = False
        self._clock_ns = clock_ns
        self._samples: deque[TruthSample] = deque(maxlen=SAMPLES_KEPT)
        rate = config.request_rate_hz
        self._burst_ns = BURST_NS if rate <= 0 else min(BURST_NS, round(0.25e9 / rate))
        self._truth: dict[int, tuple[KinematicState, FrameTruth]] = {}
        self._task: asyncio.Task[None] | None = None
        self._t0_ns: int | None = None
        self._next = 0
        self._stalled = False
        self._closed = False

    # ------------------------------------------------------------ truth in
    async def _collect(self) -> None:
        gen = self.bridge.subscribe(*TRUTH_NAMES)
        try:
            async for item in gen:
                self.heard[item.name] = self.heard.get(item.name, 0) + 1
                if item.name != FULL_TRUTH.get(self.profile):
                    continue
                sample = truth_sample(item, self.origin)
                if sample is not None:
                    add_sample(self._samples, sample, self._burst_ns)
        except asyncio.CancelledError:
            pass
        finally:
            aclose = getattr(gen, "aclose", None)
            if aclose is not None:
                with contextlib.suppress(Exception):
                    await aclose()

    def _ask_for_truth(self) -> None:
        self._asked = True
        want = FULL_TRUTH.get(self.profile)
        if self._request is None or want is None or self.config.request_rate_hz <= 0:
            return
        interval_us = 1e6 / self.config.request_rate_hz
        self._request(command=MAV_CMD_SET_MESSAGE_INTERVAL, param1=float(MESSAGE_IDS[want]),
                      param2=float(interval_us))

    async def start(self) -> None:
        """Subscribe, ask for the truth stream and wait for the first sample.

        Raises a one-line :class:`SourceError` naming the message when none comes in
        ``truth_timeout_s`` (kept in :attr:`failure` too)."""
        if self._task is None:
            self._task = asyncio.create_task(self._collect(), name="follow-truth")
        deadline = self._clock_ns() + int(self.config.truth_timeout_s * 1e9)
        next_ask = 0
        while not self._samples:
            now = self._clock_ns()
            if now >= deadline:
                self.failure = SourceError(missing_truth_message(
                    self.profile, self.heard, self.bridge.link_up, self.config.truth_timeout_s))
                raise self.failure
            if self.bridge.link_up and now >= next_ask:
                self._ask_for_truth()
                next_ask = now + 1_000_000_000
            await asyncio.sleep(0.02)
        while not self._asked and self._clock_ns() < deadline:
            # it already streams: ask anyway (once the link is up), for the configured rate
            if self.bridge.link_up:
                self._ask_for_truth()
                break
            await asyncio.sleep(0.02)
        log.info("follow camera: the simulator's truth (%s) arrives",
                 FULL_TRUTH.get(self.profile))

    def truth_rate_hz(self) -> float:
        """Mean rate of the recent truth samples (0 when fewer than two)."""
        s = self._samples
        if len(s) < 2 or s[-1].t_ns == s[0].t_ns:
            return 0.0
        return (len(s) - 1) / ((s[-1].t_ns - s[0].t_ns) / 1e9)

    # ------------------------------------------------------------ frames out
    def truth(self, index: int) -> FrameTruth | None:
        """What frame ``index`` showed (boxes, camera pose), for recent frames."""
        item = self._truth.get(index)
        return None if item is None else item[1]

    def rendered_state(self, index: int) -> KinematicState | None:
        """The interpolated vehicle state frame ``index`` was rendered from."""
        item = self._truth.get(index)
        return None if item is None else item[0]

    def truth_position(self, frame: Frame) -> tuple[float, float, float] | None:
        """The true position (flight NED, m) ``frame`` was rendered from, for recent frames
        (:class:`companion.sources.base.KnowsTruth`)."""
        state = self.rendered_state(frame.index)
        if state is None:
            return None
        n, e, d = (float(v) for v in state.position_ned_m)
        return (n, e, d)

    async def recv(self) -> Frame:
        """The next frame, due every ``1 / fps`` s, showing the world ``delay_ms`` ago;
        the frames due while nobody asked for one are skipped (``late``)."""
        if self._closed:
            raise EOFError("source closed")
        if self._t0_ns is None:
            await self.start()
            self._t0_ns = self._clock_ns()
        period_ns = 1e9 / self.fps
        while True:
            now = self._clock_ns()
            # a camera takes its frames on time: those nobody read while the companion was
            # busy are gone, and the next one shows now (a frame stamped with a slot long
            # past makes every fix stale: the coupled hover's EKF failsafe under load)
            self._next = self.status.catch_up(self._next, int((now - self._t0_ns) // period_ns),
                                              f"the companion fell behind at frame {self._next}")
            due = self._t0_ns + round(self._next * period_ns)
            delay_s = (due - now) / 1e9
            if delay_s > 0:
                await asyncio.sleep(delay_s)
            index, self._next = self._next, self._next + 1
            shown_ns = due - round(self.config.delay_ms * 1e6)
            state = self._fresh_state(shown_ns)
            if state is None:
                continue  # stale truth: no frame for this slot
            image, truth = await asyncio.get_running_loop().run_in_executor(
                None, self._render, state, index, (shown_ns - self._t0_ns) / 1e9)
            self._keep(index, state, truth)
            self.status.delivered += 1
            return Frame(index, shown_ns // 1000, image, self.camera_id)

    def _fresh_state(self, shown_ns: int) -> KinematicState | None:
        age_ms = (self._clock_ns() - self._samples[-1].t_ns) / 1e6
        state = None
        if age_ms <= self.config.stale_ms:
            state = state_at(self._samples, shown_ns,
                             round(self.config.max_extrapolation_ms * 1e6),
                             round(self.config.stale_ms * 1e6))
        if state is None:
            if not self._stalled:
                self._stalled = True
                self.status.stalls += 1
                self.status.last_error = (f"truth ({FULL_TRUTH.get(self.profile)}) "
                                          f"{age_ms:.0f} ms old: no frames")
                log.warning("follow camera: %s", self.status.last_error)
            self.status.skip("stale-truth", self.status.last_error)
            return None
        if self._stalled:
            self._stalled = False
            log.info("follow camera: truth is back")
        return state

    def _render(self, state: KinematicState, index: int, t_s: float
                ) -> tuple[ImageU8, FrameTruth]:
        """Simulator.render for a given state (not the scripted one), effects at ``t_s``."""
        return self.sim.render_state(state, index, t_s)

    def _keep(self, index: int, state: KinematicState, truth: FrameTruth) -> None:
        self._truth[index] = (state, truth)
        while len(self._truth) > TRUTH_KEPT:
            del self._truth[next(iter(self._truth))]

    def close(self) -> None:
        """Stop delivering and stop listening to the truth stream."""
        self._closed = True
        if self._task is not None:
            self._task.cancel()
            self._task = None


def command_sender(bridge: object) -> Callable[..., None] | None:
    """A COMMAND_LONG sender over the pymavlink backend's link (None for other backends)."""
    link = getattr(bridge, "link", None)
    if link is None or not callable(getattr(link, "send", None)):
        return None

    def send(command: int, param1: float = 0.0, param2: float = 0.0) -> None:
        link.send("COMMAND_LONG", target_system=getattr(link, "autopilot_sysid", None) or 1,
                  target_component=1, command=command, confirmation=0, param1=param1,
                  param2=param2, param3=0.0, param4=0.0, param5=0.0, param6=0.0, param7=0.0)

    return send


def follow_simulator(scenario: ScenarioConfig, landmarks_path: str, origin: LocalFrame
                     ) -> Simulator:
    """The scenario's world with the flight's landmark map placed about the EKF origin."""
    o = OriginConfig(origin.lat_deg, origin.lon_deg, origin.alt_m)
    return Simulator(replace(scenario, origin=o, landmarks=landmarks_path))
