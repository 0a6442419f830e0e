"""Which messages the fake autopilot sends, and when: a real autopilot's stream rules.

``strict`` (the default) is what a real port does: HEARTBEAT at 1 Hz and, on PX4, TIMESYNC
requests at 10 Hz (PX4 ``src/modules/mavlink/mavlink_timesync.cpp`` on onboard links) and
nothing else until asked (ArduPilot's stream-rate parameters SRn_* / MAVn_* default to 0 on
SITL and many serial ports, ../shared/MAVLINK.md "What a real ArduCopter did").

* MAV_CMD_SET_MESSAGE_INTERVAL (511): param1 message id, param2 interval in us; ``-1``
  stops the stream, ``0`` restores the default rate (ArduPilot
  ``libraries/GCS_MAVLink/GCS_Common.cpp`` ``handle_command_set_message_interval``; PX4
  ``src/modules/mavlink/mavlink_receiver.cpp`` ``set_message_interval``).  ACK ACCEPTED, or
  FAILED for a message this autopilot cannot send.
* MAV_CMD_REQUEST_MESSAGE (512): param1 message id, sent once.
* Both keep the intervals in RAM only: a reboot forgets them (:meth:`FakeStreams.reset`).

``all`` is the old permissive fake: every stream at its default period without asking, for
the tests that need it.  ``absent`` messages are accepted but never sent (a sensor that is
not fitted: ArduPilot accepts an interval for DISTANCE_SENSOR and sends nothing without a
range finder).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal

from mavlink_bridge.streams import MESSAGE_NAMES

StreamMode = Literal["strict", "all"]
MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED = 0, 4
_EXTRA_IDS = {"TIMESYNC": 111, "HEARTBEAT": 0}
#: Sent whatever was asked (per profile).
_ALWAYS: dict[str, tuple[str, ...]] = {"ardupilot": ("HEARTBEAT",),
                                       "px4": ("HEARTBEAT", "TIMESYNC")}


class FakeStreams:
    """The active stream periods; ``due(now_s)`` yields what to send now."""

    def __init__(self, mode: StreamMode, profile: str, defaults: Iterable[tuple[str, float]],
                 sendable: frozenset[str], absent: Iterable[str] = ()) -> None:
        self.mode = mode
        self.profile = profile
        self.defaults = dict(defaults)
        self.sendable = sendable  # what this fake can send at all (profile, truth)
        self.absent = frozenset(absent)
        self.periods: dict[str, float] = {}
        self._next_due: dict[str, float] = {}
        self._once: list[str] = []
        self.asked: list[tuple[str, float]] = []  # every interval asked (name, period; -1 stop)
        self.reset()

    def reset(self) -> None:
        """Boot: strict forgets every asked interval; all restores the defaults."""
        if self.mode == "all":
            self.periods = {n: p for n, p in self.defaults.items() if n in self.sendable}
        else:
            self.periods = {n: self.defaults.get(n, 1.0) for n in _ALWAYS[self.profile]
                            if n in self.sendable}
        self._next_due = {}
        self._once = []

    def set_interval(self, message_id: int, interval_us: float) -> int:
        """SET_MESSAGE_INTERVAL -> MAV_RESULT."""
        name = MESSAGE_NAMES.get(message_id) or next(
            (n for n, i in _EXTRA_IDS.items() if i == message_id), None)
        if name is None or name not in self.sendable:
            return MAV_RESULT_FAILED
        if interval_us < 0:
            self.periods.pop(name, None)
            self.asked.append((name, -1.0))
            return MAV_RESULT_ACCEPTED
        period = self.defaults.get(name, 1.0) if interval_us == 0 else interval_us * 1e-6
        self.periods[name] = period
        self._next_due.pop(name, None)
        self.asked.append((name, period))
        return MAV_RESULT_ACCEPTED

    def request_once(self, message_id: int) -> int:
        """REQUEST_MESSAGE -> MAV_RESULT; the message goes out with the next :meth:`due`."""
        name = MESSAGE_NAMES.get(message_id)
        if name is None or name not in self.sendable:
            return MAV_RESULT_FAILED
        self._once.append(name)
        return MAV_RESULT_ACCEPTED

    def due(self, now_s: float) -> list[str]:
        """The messages to send now (an absent sensor's never)."""
        out, self._once = [n for n in self._once if n not in self.absent], []
        for name, period in self.periods.items():
            if name in self.absent:
                continue
            if now_s >= self._next_due.get(name, 0.0):
                self._next_due[name] = now_s + period
                out.append(name)
        return out
