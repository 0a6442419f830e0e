"""The fake autopilot replaying a recording's telemetry (``companion replay``).

A stream recorded from a live autopilot (format version 2, docs/formats.md) carries the
messages the companion consumed beside the frames: ATTITUDE, LOCAL_POSITION_NED,
DISTANCE_SENSOR, GLOBAL_POSITION_INT, each with the time it arrived on the stream's clock.
:class:`TelemetryReplay` plugs into :class:`~mavlink_bridge.fake_autopilot.FakeAutopilot`
(its ``replay``): for a replayed message the fake sends, instead of its own estimate, the
newest recorded message whose recorded time has come on the fake's clock (the fake's
flight time is the recording's time, ``companion.replay`` maps it onto the companion's).

What stays the strict fake's:

* A stream goes out only once asked with SET_MESSAGE_INTERVAL, and at most at the asked
  interval: ArduPilot sends a message when its interval is due from the deferred message
  buckets, built from the vehicle's *current* state at that moment
  (``libraries/GCS_MAVLink/GCS_Common.cpp`` ``update_send`` / ``try_send_message``, e.g.
  ``send_attitude`` reads AP_AHRS then).  The replay's current state is the newest recorded
  message, sent when its recorded time comes; one already sent is not sent again (a repeat
  would carry a new arrival time for an old attitude), so a stream asked faster than it was
  recorded arrives at the recorded rate, and one asked slower is thinned to the asked rate.
  A REQUEST_MESSAGE (once) of a replayed message sends nothing (not needed by the
  companion's streams).
* ``time_boot_ms`` is the fake's own boot time when sent, never the recorded one: the
  companion detects an autopilot reboot by ``time_boot_ms`` going backwards
  (``mavlink_bridge/link.py``), as it would on a real link.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mavlink_bridge.vehicle import TruthFn, VehicleState

#: The messages a version-2 stream records and the replay sends.
REPLAYED = ("ATTITUDE", "LOCAL_POSITION_NED", "DISTANCE_SENSOR", "GLOBAL_POSITION_INT")


@dataclass(frozen=True)
class RecordedMessage:
    """One recorded message: its arrival time on the stream's clock (s) and its fields."""

    time_s: float
    name: str
    fields: Mapping[str, Any]


class TelemetryReplay:
    """The recorded messages by name, each sent once when due (see module doc)."""

    def __init__(self, messages: Sequence[RecordedMessage]) -> None:
        self.by_name: dict[str, list[RecordedMessage]] = {}
        for m in sorted(messages, key=lambda m: m.time_s):
            if m.name in REPLAYED:
                self.by_name.setdefault(m.name, []).append(m)
        self._times = {n: [m.time_s for m in ms] for n, ms in self.by_name.items()}
        self._sent: dict[str, int] = {}
        #: messages sent per name (for tests and the replay's summary)
        self.sent: dict[str, int] = dict.fromkeys(self.by_name, 0)
        #: the fake's flight time of the recording's time 0 (infinite: not started)
        self.offset_s = math.inf

    def start(self, offset_s: float) -> None:
        """The recording starts at the fake's flight time ``offset_s``."""
        self.offset_s = offset_s

    def covers(self, name: str) -> bool:
        """True when the recording has this message: the fake then sends only those."""
        return name in self.by_name

    def pump(self, mav: Any, periods: Mapping[str, float], now_s: float,
             boot_ms: int) -> int:
        """Send, for each recorded message whose stream is asked (``periods``: name ->
        asked period, s), the newest one recorded by the fake's flight time ``now_s`` (less
        :attr:`offset_s`) if it is at least 0.9 of
        the asked period after the last one sent (10 % slack: a 30 Hz recording under a
        30 Hz ask is not halved by its jitter).  Returns how many were sent."""
        count = 0
        for name, times in self._times.items():
            period = periods.get(name)
            i = bisect.bisect_right(times, now_s - self.offset_s) - 1
            last = self._sent.get(name, -1)
            if period is None or i <= last or (last >= 0 and times[i] - times[last]
                                               < 0.9 * period):
                continue
            self._sent[name] = i
            self.sent[name] += 1
            fields = {**self.by_name[name][i].fields, "time_boot_ms": boot_ms}
            getattr(mav, f"{name.lower()}_send")(**fields)
            count += 1
        return count

    def trajectory(self) -> TruthFn | None:
        """The recorded flight (LOCAL_POSITION_NED and ATTITUDE, held between samples) as
        the fake's truth, for a recording without ``truth_pose.csv``; None without
        LOCAL_POSITION_NED."""
        positions = self.by_name.get("LOCAL_POSITION_NED")
        if not positions:
            return None
        attitudes = self.by_name.get("ATTITUDE", [])
        p_times, a_times = self._times["LOCAL_POSITION_NED"], self._times.get("ATTITUDE", [])

        def truth(t: float) -> VehicleState:
            p = positions[max(bisect.bisect_right(p_times, t) - 1, 0)].fields
            a = attitudes[max(bisect.bisect_right(a_times, t) - 1, 0)].fields \
                if attitudes else {}
            rpy = (float(a.get("roll", 0.0)), float(a.get("pitch", 0.0)),
                   float(a.get("yaw", 0.0)))
            d = float(p["z"])
            return VehicleState(t, (float(p["x"]), float(p["y"]), d),
                                (float(p["vx"]), float(p["vy"]), float(p["vz"])), rpy,
                                max(-d, 0.0) / max(math.cos(rpy[0]) * math.cos(rpy[1]), 0.1))

        return truth
