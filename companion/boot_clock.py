"""The autopilot's ``time_boot_ms`` on the companion's clock.

A sample stamped with its arrival carries the link's delay, and after a stall of the
companion's event loop (or a burst on a serial port) several samples sent over tens of
milliseconds arrive within microseconds: their arrival stamps say "now" while their values
span the stall.  The autopilot's own stamp does not move with the link:

* ArduPilot stamps ATTITUDE, LOCAL_POSITION_NED and DISTANCE_SENSOR with
  ``AP_HAL::millis()`` when it sends them (``GCS_MAVLINK::send_attitude``); its AHRS is
  updated at the main loop's rate (400 Hz on Copter), so the stamp is within a loop of the
  estimate's time.
* PX4 stamps ATTITUDE with its ``vehicle_attitude`` estimate's own timestamp.

:class:`BootClock` maps the stamp onto the companion's clock by the smallest
``arrival - boot`` over a sliding window (the least delayed message of the window: a
minimum-delay filter, as NTP's clock filter picks the sample with the least delay).  The
mapped time is never later than the arrival.  ``time_boot_ms`` stepping back by more than
:data:`REBOOT_BACKSTEP_MS` (the link's reboot rule) starts the estimate again; a sender that
leaves the field 0 keeps its arrival stamps.
"""

from __future__ import annotations

from collections import deque

from mavlink_bridge.link import REBOOT_BACKSTEP_MS

#: how far back the minimum-delay offset looks (drift between the clocks over it: < 1 ms)
WINDOW_US = 10_000_000


class BootClock:
    """``time_boot_ms`` -> the companion's clock (us), by a sliding minimum-delay offset."""

    def __init__(self, window_us: int = WINDOW_US) -> None:
        self.window_us = window_us
        # (arrival us, arrival - boot us), offsets increasing: the front is the window's min
        self._offsets: deque[tuple[int, int]] = deque()
        self._last_boot_ms = -1
        #: how often time_boot_ms stepped back (the estimate started again)
        self.restarts = 0

    def stamp(self, boot_ms: int, arrival_us: int) -> int:
        """The companion-clock time (us) of a message stamped ``boot_ms`` that arrived at
        ``arrival_us``."""
        if boot_ms <= 0:
            return arrival_us  # the sender does not fill the field
        if 0 <= self._last_boot_ms and boot_ms + REBOOT_BACKSTEP_MS < self._last_boot_ms:
            self._offsets.clear()
            self.restarts += 1
        self._last_boot_ms = boot_ms
        offset = arrival_us - boot_ms * 1000
        q = self._offsets
        while q and q[-1][1] >= offset:
            q.pop()
        q.append((arrival_us, offset))
        while q[0][0] < arrival_us - self.window_us:
            q.popleft()
        return min(arrival_us, boot_ms * 1000 + q[0][1])

    def offset_us(self) -> int | None:
        """The current offset (companion us - boot us), None before a stamped message."""
        return self._offsets[0][1] if self._offsets else None
