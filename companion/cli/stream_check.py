"""``companion autopilot setup``'s stream check: ask for what the companion will ask for, say
what arrives.

The companion needs no stream-rate parameter (ArduPilot's ``SRn_*`` / ``MAVn_*``, PX4's
``mavlink stream``): it asks for every message it uses with MAV_CMD_SET_MESSAGE_INTERVAL at
each link-up and reboot (:mod:`mavlink_bridge.streams`). Setup asks the same way, watches for
``wait_s`` and prints per stream "arriving at N Hz", "slow" or "missing", so a port or a
firmware that does not honour the request is found before the flight. Afterwards each
interval is set back to the autopilot's default (interval 0).

ArduPilot sends LOCAL_POSITION_NED only once its EKF has an origin, which the companion sets
when it starts (``mavlink.set_origin``), so before a flight its absence is said, not counted
as missing. (PX4's stream sends whenever its estimator publishes a local position, valid or
not: there an absence means the estimator has not started. The fake applies ArduPilot's rule
to both profiles.)
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence

from mavlink_bridge.link import MavlinkLink
from mavlink_bridge.streams import StreamSpec, StreamWatch, interval_command

#: Streams an autopilot sends only once its estimator has a position.
AFTER_A_POSITION = frozenset({"LOCAL_POSITION_NED"})


def _request(link: MavlinkLink) -> Callable[[str, int], None]:
    def request(name: str, interval_us: int) -> None:
        link.send("COMMAND_LONG", target_system=link.autopilot_sysid or 1, target_component=1,
                  confirmation=0, **interval_command(name, interval_us))
    return request


async def check_streams(link: MavlinkLink, specs: Sequence[StreamSpec], wait_s: float,
                        clock_ns: Callable[[], int] = time.monotonic_ns) -> list[str]:
    """Ask for ``specs``, print what arrived after ``wait_s``; -> the streams missing or slow."""
    if not specs:
        return []
    request = _request(link)
    watch = StreamWatch(specs, request, lambda _text, _severity: None)

    def heard(msg: object) -> None:
        watch.on_message(msg.get_type(), clock_ns())  # type: ignore[attr-defined]

    link.add_msg_listener(heard)
    try:
        watch.ask_all(clock_ns())
        end = clock_ns() + int(wait_s * 1e9)
        while clock_ns() < end:
            await asyncio.sleep(0.25)
            watch.tick(clock_ns())
    finally:
        link.remove_msg_listener(heard)
        for s in specs:
            request(s.name, 0)  # the autopilot's default rate again
    print("streams (the companion asks for them itself at every link-up and reboot with "
          "SET_MESSAGE_INTERVAL; no stream-rate parameter is needed):")
    report = watch.report(clock_ns())
    later = [n for n in watch.missing() if n in AFTER_A_POSITION and report[n]["rate_hz"] == 0]
    for s in specs:
        r = report[s.name]
        seen = {"missing": "MISSING", "slow": f"SLOW at {r['rate_hz']:g} Hz",
                "asked": "nothing yet (watched too briefly to tell)"}.get(
            str(r["state"]), f"arriving at {r['rate_hz']:g} Hz")
        if seen == "arriving at 0 Hz":  # heard once: its rate needs two
            seen = "heard (watched too briefly to measure its rate)"
        if s.name in later:
            seen = "none yet (ArduPilot sends it once the EKF has an origin, which the " \
                "companion sets when it starts)"
        print(f"  {s.name:<22} asked {s.rate_hz:g} Hz: {seen}  ({s.why})")
    return [n for n in watch.missing() if n not in later]
