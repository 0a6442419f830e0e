"""Ask the autopilot for the messages the companion uses, and watch that they arrive.

A real autopilot port streams nothing but HEARTBEAT until asked: ArduPilot's stream-rate
parameters (SRn_* / MAVn_* in 4.7) are 0 on SITL and on many serial ports, and PX4's onboard
mode streams a fixed set.  So on link-up and after every autopilot reboot the companion sends
MAV_CMD_SET_MESSAGE_INTERVAL (511) for each message it needs: param1 the message id, param2
the interval in microseconds (> 0; ``-1`` stops a stream, ``0`` asks for the autopilot's
default rate -- ArduPilot ``libraries/GCS_MAVLink/GCS_Common.cpp``
``handle_command_set_message_interval``, PX4 ``src/modules/mavlink/mavlink_receiver.cpp``
``set_message_interval``).  Both answer COMMAND_ACK (ACCEPTED, or FAILED/UNSUPPORTED for a
message they cannot send) and keep the intervals in RAM only: a reboot forgets them
(../shared/MAVLINK.md, "What a real ArduCopter did").

:class:`StreamWatch` measures each stream's arrival rate, asks again (with back-off) while one
is missing, and reports per stream ``asked`` / ``arriving`` / ``slow`` / ``missing``.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Literal

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
#: MAVLink message ids of what the companion may ask for (common.xml / ardupilotmega.xml).
MESSAGE_IDS: dict[str, int] = {
    "ATTITUDE": 30, "LOCAL_POSITION_NED": 32, "GLOBAL_POSITION_INT": 33,
    "DISTANCE_SENSOR": 132, "EKF_STATUS_REPORT": 193, "SIM_STATE": 108, "SIMSTATE": 164,
    "HIL_STATE_QUATERNION": 115, "SYSTEM_TIME": 2, "HOME_POSITION": 242, "ODOMETRY": 331,
}
MESSAGE_NAMES: dict[int, str] = {v: k for k, v in MESSAGE_IDS.items()}
log = logging.getLogger(__name__)
MAV_SEVERITY_WARNING, MAV_SEVERITY_INFO = 4, 6
StreamState = Literal["asked", "arriving", "slow", "missing"]
#: A stream arriving below this share of the asked rate is "slow".
SLOW_SHARE = 0.5


@dataclass(frozen=True)
class StreamSpec:
    """One message the companion asks for, at ``rate_hz``, and why it needs it."""

    name: str
    rate_hz: float
    why: str = ""

    @property
    def interval_us(self) -> int:
        return round(1e6 / self.rate_hz)


def needed_streams(camera_fps: float, *, profile: str = "ardupilot", rangefinder: bool = False,
                   follow: bool = False) -> tuple[StreamSpec, ...]:
    """The streams a configuration needs -- the one place this is decided.

    ATTITUDE at least at the camera rate (the pose solver looks up the attitude at each
    frame's time; 10 Hz minimum); LOCAL_POSITION_NED (down: the height prior; the monitor
    plots fixes against it) and GLOBAL_POSITION_INT (relative altitude; proves the EKF origin
    is set); DISTANCE_SENSOR with a range finder; EKF_STATUS_REPORT on ArduPilot (PX4 has no
    such stream) to watch the EKF accept the fixes; ODOMETRY on PX4, whose attitude variance
    widens the attitude prior (:mod:`companion.sensors`); the simulator's truth only in
    follow mode (SIM_STATE on ArduPilot SITL, HIL_STATE_QUATERNION on PX4).
    """
    att_hz = float(min(50, max(10, math.ceil(camera_fps))))
    out = [StreamSpec("ATTITUDE", att_hz, "attitude prior of the pose solver"),
           StreamSpec("LOCAL_POSITION_NED", 10.0, "height prior, monitoring"),
           StreamSpec("GLOBAL_POSITION_INT", 5.0, "relative altitude, EKF origin")]
    if rangefinder:
        out.append(StreamSpec("DISTANCE_SENSOR", 20.0, "range finder for the height prior"))
    if profile == "ardupilot":
        out.append(StreamSpec("EKF_STATUS_REPORT", 2.0, "EKF health monitoring"))
    else:  # PX4 states its EKF's attitude variance there (ArduPilot nowhere)
        out.append(StreamSpec("ODOMETRY", 5.0, "the EKF's attitude variance (attitude prior)"))
    if follow:
        truth = "SIM_STATE" if profile == "ardupilot" else "HIL_STATE_QUATERNION"
        out.append(StreamSpec(truth, 50.0, "follow mode: the simulator's true pose"))
    return tuple(out)


def interval_command(name: str, interval_us: int) -> dict[str, float]:
    """COMMAND_LONG params of SET_MESSAGE_INTERVAL (param7 0: the flight stack's default
    response target, i.e. this link)."""
    return {"command": MAV_CMD_SET_MESSAGE_INTERVAL, "param1": float(MESSAGE_IDS[name]),
            "param2": float(interval_us), "param3": 0.0, "param4": 0.0, "param5": 0.0,
            "param6": 0.0, "param7": 0.0}


@dataclass
class _Stream:
    spec: StreamSpec
    state: StreamState = "asked"
    since_ns: int | None = None  # the last ask_all (link-up, reboot)
    asked_ns: int = 0  # the last request
    last_ns: int | None = None
    back_ns: int | None = None  # the first arrival after it went missing
    retry_s: float = 0.0
    requests: int = 0
    arrivals: collections.deque[int] = field(default_factory=lambda: collections.deque(maxlen=200))


class StreamWatch:
    """Ask for ``specs`` with ``request(name, interval_us)``; watch their arrival.

    When a stream goes missing or slow: one warning log line and one STATUSTEXT (through
    ``statustext(text, severity)``) per episode; one info line when it arrives again.
    """

    def __init__(self, specs: Iterable[StreamSpec], request: Callable[[str, int], None],
                 statustext: Callable[[str, int], None], *, window_s: float = 2.0,
                 first_retry_s: float = 0.5, max_retry_s: float = 8.0) -> None:
        self._streams = {s.name: _Stream(s) for s in specs}
        self._request = request
        self._statustext = statustext
        self.window_s = window_s
        self.first_retry_s = first_retry_s
        self.max_retry_s = max_retry_s
        self.asked_all = 0

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._streams)

    def ask_all(self, now_ns: int) -> None:
        """Link-up or reboot: the autopilot forgot every interval; ask for all of them."""
        self.asked_all += 1
        for s in self._streams.values():
            s.retry_s = self.first_retry_s
            s.since_ns = now_ns
            s.arrivals.clear()
            self._ask(s, now_ns)

    def _ask(self, s: _Stream, now_ns: int) -> None:
        s.asked_ns = now_ns
        s.requests += 1
        self._request(s.spec.name, s.spec.interval_us)

    def on_message(self, name: str, now_ns: int) -> None:
        s = self._streams.get(name)
        if s is not None:
            if s.state == "missing":
                s.back_ns = now_ns
            s.last_ns = now_ns
            s.arrivals.append(now_ns)

    def rate_hz(self, name: str, now_ns: int) -> float:
        """Arrivals per second over the last ``window_s`` (0 with fewer than two)."""
        s = self._streams[name]
        window_s = max(self.window_s, 6.0 / s.spec.rate_hz)  # >= 6 periods of a slow stream
        start = now_ns - int(window_s * 1e9)
        recent = [t for t in s.arrivals if t >= start]
        if len(recent) < 2:
            return 0.0
        span_s = max((now_ns - recent[0]) * 1e-9, 1e-3)
        return (len(recent) - 1) / span_s

    def tick(self, now_ns: int) -> None:
        """Update each stream's state; ask again for a missing one (back-off doubling)."""
        for s in self._streams.values():
            if s.since_ns is None:
                continue
            state = self._state_of(s, now_ns)
            if state != s.state:
                self._announce(s, state, now_ns)
                s.state = state
            if state == "missing" and (now_ns - s.asked_ns) * 1e-9 >= s.retry_s:
                self._ask(s, now_ns)
                s.retry_s = min(self.max_retry_s, s.retry_s * 2.0)
            elif state in ("arriving", "slow"):
                s.retry_s = self.first_retry_s

    def _state_of(self, s: _Stream, now_ns: int) -> StreamState:
        """Missing when nothing came for five periods (at least 0.5 s) after being asked."""
        silence_s = max(0.5, 5.0 / s.spec.rate_hz)
        assert s.since_ns is not None
        last = s.last_ns if s.last_ns is not None and s.last_ns >= s.since_ns else None
        if (now_ns - (last if last is not None else s.since_ns)) * 1e-9 > silence_s:
            return "missing"
        if last is None:
            return "asked"
        began = s.since_ns if s.back_ns is None else max(s.since_ns, s.back_ns)
        if (now_ns - began) * 1e-9 < max(self.window_s, 6.0 / s.spec.rate_hz):
            return "arriving"  # too early to judge the rate (asked, or back after a silence)
        rate = self.rate_hz(s.spec.name, now_ns)
        return "arriving" if rate >= SLOW_SHARE * s.spec.rate_hz else "slow"

    def _announce(self, s: _Stream, state: StreamState, now_ns: int) -> None:
        name, hz = s.spec.name, s.spec.rate_hz
        if state == "missing":
            self._warn(f"{name} missing (asked {hz:g} Hz)")
        elif state == "slow":
            self._warn(f"{name} slow: {self.rate_hz(name, now_ns):.1f} of {hz:g} Hz")
        elif state == "arriving" and s.state in ("missing", "slow"):
            log.info("autopilot stream %s arriving again", name)
            self._statustext(f"{name} arriving", MAV_SEVERITY_INFO)

    def _warn(self, text: str) -> None:
        log.warning("autopilot stream %s: asking again with SET_MESSAGE_INTERVAL "
                    "(docs/mavlink.md, streams)", text)
        self._statustext(text, MAV_SEVERITY_WARNING)

    def missing(self) -> list[str]:
        return [n for n, s in self._streams.items() if s.state in ("missing", "slow")]

    def report(self, now_ns: int) -> dict[str, dict[str, float | int | str]]:
        """Per stream: ``asked_hz``, measured ``rate_hz``, ``state``, ``requests`` sent."""
        return {n: {"asked_hz": s.spec.rate_hz, "rate_hz": round(self.rate_hz(n, now_ns), 1),
                    "state": s.state,
                    "requests": s.requests}
                for n, s in self._streams.items()}


async def keep_streams(watch: StreamWatch, link_up: Callable[[], bool],
                       clock_ns: Callable[[], int], period_s: float) -> None:
    """The watch's task: tick every ``period_s`` while the link is up."""
    while True:
        await asyncio.sleep(period_s)
        if link_up():
            watch.tick(clock_ns())


def parse_streams(pairs: Iterable[tuple[str, float]]) -> tuple[StreamSpec, ...]:
    """``MavlinkConfig.streams`` -> specs; an unknown name is a ValueError naming it."""
    out = []
    for name, hz in pairs:
        if name not in MESSAGE_IDS:
            raise ValueError(f"mavlink.streams: unknown message {name!r}; known: "
                             + ", ".join(sorted(MESSAGE_IDS)))
        out.append(StreamSpec(name, float(hz)))
    return tuple(out)
