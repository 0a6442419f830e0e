"""``companion autopilot setup``: the autopilot parameters a profile needs, set from here.

A user of the bare SITL binary, or of a vehicle on a serial port with no ground station, has
no other way to set them.  Shows current against wanted (mavlink_bridge/params.py has the
table and where each default comes from), sets only after confirmation (or ``--yes``), reads
each back, and says which need a reboot.  ``VISO_DELAY_MS`` / ``EKF2_EV_DELAY`` come from the
companion's measured capture-to-wire latency: ``--delay-ms``, or the last status of a flight
log (``--flightlog``): for ArduPilot its least latency while its p50 is inside EKF3's
fusion horizon (60 ms), since ArduPilot's jitter correction has already placed each fix by
the quickest one's lag, and its p50 beyond, where EKF3 takes every fix at its arrival less
``VISO_DELAY_MS`` (docs/mavlink.md, "Timestamps"); for PX4 its p50 plus
:data:`DELAY_MARGIN_MS`; else :data:`mavlink_bridge.params.DEFAULT_DELAY_MS`.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import sys
from pathlib import Path

from companion.cli.stream_check import check_streams
from companion.errors import ConfigError, InputError, LinkError
from companion.flightlog import read_flight_log
from companion.runtime import stream_specs
from companion.settings import Settings
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.errors import EndpointError, LinkOpenError
from mavlink_bridge.link import MavlinkLink
from mavlink_bridge.params import (
    DEFAULT_DELAY_MS,
    EKF3_HORIZON_FLOOR_MS,
    ParamClient,
    ParamSpec,
    needs_reboot,
    parameter_specs,
    same_value,
)
from mavlink_bridge.streams import StreamSpec

#: Added to the measured p50: the delay must cover most fixes, not half of them.
DELAY_MARGIN_MS = 10.0
#: How long setup watches the streams it asked for: past the 2 Hz stream's missing time.
STREAMS_S = 3.5


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion autopilot setup``."""
    parser = sub.add_parser(
        "autopilot", help="set up the autopilot's parameters for external navigation",
        description="Autopilot set-up over MAVLink, without a ground station.")
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    setup = actions.add_parser(
        "setup", help="show, set and read back the parameters the profile needs",
        description="Show the parameters the profile needs (current -> wanted), set them "
        "after confirmation (or --yes), read them back and say whether a reboot is needed.")
    setup.add_argument("--profile", choices=("ardupilot", "px4"),
                       help="which autopilot (default: vehicle.profile)")
    setup.add_argument("--endpoint", metavar="SPEC",
                       help="the autopilot link (default: mavlink.endpoint), e.g. "
                       "tcp:127.0.0.1:5760 or serial:/dev/ttyACM0:115200")
    setup.add_argument("--yes", action="store_true", help="set without asking")
    setup.add_argument("--delay-ms", type=float, metavar="MS",
                       help="the companion's latency for VISO_DELAY_MS / EKF2_EV_DELAY")
    setup.add_argument("--flightlog", type=Path, metavar="FILE.jsonl",
                       help="take the latency from this flight log's last status (ArduPilot: "
                       f"its least; PX4: p50 + {DELAY_MARGIN_MS:g} ms)")
    setup.add_argument("--timeout", type=float, default=10.0, metavar="S",
                       help="wait this long for the autopilot's heartbeat (default: 10)")
    setup.add_argument("--streams-s", type=float, default=STREAMS_S, metavar="S",
                       help="ask for the streams the companion uses and watch them this "
                       f"long (default: {STREAMS_S:g}; 0: skip)")
    setup.set_defaults(handler=run)


def delay_from(args: argparse.Namespace, profile: str) -> tuple[float, str]:
    """The delay to set and where it came from."""
    if args.delay_ms is not None:
        if not 0 <= args.delay_ms <= 250:
            raise ConfigError(f"--delay-ms: expected 0..250, got {args.delay_ms:g}")
        return float(args.delay_ms), "--delay-ms"
    if args.flightlog is not None:
        log = read_flight_log(args.flightlog)
        measured = [r["latency_ms"] for r in log.records if r.get("kind") == "status"
                    and isinstance(r.get("latency_ms", {}).get("p50"), int | float)]
        if not measured:
            raise InputError(f"{args.flightlog}: no measured latency in its status records")
        least, p50 = measured[-1].get("min"), measured[-1]["p50"]
        if profile == "ardupilot" and isinstance(least, int | float):
            if p50 <= EKF3_HORIZON_FLOOR_MS:
                return float(least), f"{args.flightlog} least {least:.0f} ms"
            return min(float(p50), 250.0), (f"{args.flightlog} p50 {p50:.0f} ms (beyond "
                                            f"EKF3's {EKF3_HORIZON_FLOOR_MS:.0f} ms horizon)")
        return p50 + DELAY_MARGIN_MS, f"{args.flightlog} p50 {p50:.0f} ms + margin"
    return DEFAULT_DELAY_MS, "default (no latency measured: run the companion, then "\
        "use --flightlog)"


def run(args: argparse.Namespace, settings: Settings) -> int:
    """0: every parameter as wanted (or nothing to do); 1: declined, unanswered or refused."""
    profile = args.profile or settings.vehicle.profile
    delay, source = delay_from(args, profile)
    cfg = dataclasses.replace(settings.mavlink, endpoint=args.endpoint or
                              settings.mavlink.endpoint, profile=profile, streams=())
    if not 0 <= args.streams_s <= 60:
        raise ConfigError(f"--streams-s: expected 0..60 (0: skip), got {args.streams_s:g}")
    streams = stream_specs(settings, profile) if args.streams_s > 0 else ()
    print(f"{profile} parameters on {cfg.endpoint} (delay {delay:.0f} ms: {source})")
    return asyncio.run(_setup(cfg, parameter_specs(profile, delay), args.yes, args.timeout,
                              streams, args.streams_s))


async def _setup(cfg: MavlinkConfig, specs: tuple[ParamSpec, ...], yes: bool,
                 timeout_s: float, streams: tuple[StreamSpec, ...] = (),
                 streams_s: float = 0.0) -> int:
    try:
        link = MavlinkLink(cfg)
        await link.start()
    except (EndpointError, LinkOpenError) as err:
        raise LinkError(f"autopilot setup: {err}") from err
    try:
        link.report_health("standby")
        if not await link.wait_link(True, timeout_s):
            raise LinkError(f"autopilot setup: no autopilot heartbeat on {cfg.endpoint} "
                            f"in {timeout_s:g} s")
        status = await _parameters(link, cfg.profile, specs, yes)
        missing = await check_streams(link, streams, streams_s)
        if missing:
            print(f"autopilot setup: not arriving as asked: {', '.join(missing)} (the "
                  "companion will warn in flight; docs/mavlink.md, streams)", file=sys.stderr)
            return 1
        return status
    finally:
        await link.stop()


async def _parameters(link: MavlinkLink, profile: str, specs: tuple[ParamSpec, ...],
                      yes: bool) -> int:
    client = ParamClient(link, bytewise=profile == "px4")
    current = await client.read([p.name for p in specs])
    change = _show(specs, current)
    if not change:
        print("every parameter is as wanted: nothing to set")
        return 0
    if not yes and not _confirm(len(change)):
        print("nothing set")
        return 1
    wanted = {p.name: float(p.wanted) for p in change}
    back = await client.set(wanted, {p.name: p.integer for p in change})
    return _report(profile, change, back)


def _show(specs: tuple[ParamSpec, ...], current: dict[str, float | None]) -> list[ParamSpec]:
    """Print the table; -> the parameters to change."""
    change = []
    for p in specs:
        now = current.get(p.name)
        ok = now is not None and same_value(now, p.wanted)
        mark = "ok " if ok else "SET"
        shown = "no answer" if now is None else f"{now:g}"
        reboot = "  (reboot)" if p.reboot and not ok else ""
        print(f"  {mark} {p.name:<16} {shown:>10} -> {p.wanted:<8g} {p.why}{reboot}")
        if not ok and now is not None:
            change.append(p)
    unanswered = [p.name for p in specs if current.get(p.name) is None]
    if unanswered:
        print(f"no answer for {', '.join(unanswered)}: not on this autopilot (firmware "
              "without them?); set them with a ground station")
    return change


def _confirm(count: int) -> bool:
    try:
        answer = input(f"set {count} parameter(s)? [y/N] ")
    except EOFError:
        return False
    return answer.strip().lower() in ("y", "yes")


def _report(profile: str, change: list[ParamSpec], back: dict[str, float | None]) -> int:
    bad = [p.name for p in change if back.get(p.name) is None
           or not same_value(float(back[p.name] or 0.0), p.wanted)]
    for p in change:
        got = back.get(p.name)
        print(f"  {p.name:<16} read back {'no answer' if got is None else f'{got:g}'}")
    done = [p.name for p in change if p.name not in bad]
    reboot = needs_reboot(profile, done)
    if reboot:
        print(f"reboot the autopilot: {', '.join(reboot)} take effect only after a reboot")
    elif done:
        print("set; no reboot needed")
    if bad:
        print(f"autopilot setup: not set: {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0
