"""``companion log show|export FILE``: read a flight log."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from companion.flightlog import read_flight_log, select, write_csv
from companion.settings import Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion log``."""
    parser = sub.add_parser("log", help="show or export a flight log",
                            description="Read a flight log written by the companion.")
    actions = parser.add_subparsers(dest="log_action", metavar="ACTION", required=True)
    show = actions.add_parser("show", help="summary, then the records (newest last)")
    show.add_argument("file", type=Path)
    show.add_argument("--kind", help="only records of this kind (fix, track, event, status)")
    show.add_argument("--tail", type=int, default=20, metavar="N",
                      help="how many records to print (default 20; 0 for all)")
    export = actions.add_parser("export", help="write records as CSV or JSON")
    export.add_argument("file", type=Path)
    export.add_argument("--kind", help="only records of this kind")
    export.add_argument("--format", choices=("csv", "json"), default="csv")
    export.add_argument("--out", type=Path, help="output file (default: standard output)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Show or export."""
    log = read_flight_log(args.file)
    records = list(select(log, args.kind))
    if args.log_action == "show":
        first = log.records[0]["t_us"] if log.records else 0
        last = log.records[-1]["t_us"] if log.records else 0
        print(f"{args.file}: vehicle {log.header.get('vehicle')}, "
              f"{len(log.records)} records over {(last - first) / 1e6:.1f} s")
        print("  by kind: " + ", ".join(f"{k} {n}" for k, n in sorted(log.kinds.items())))
        if log.torn_lines:
            print(f"  {log.torn_lines} torn line(s) skipped (a crash mid-write)")
        for record in records[-args.tail:] if args.tail else records:
            print(json.dumps(record))
        return 0
    out = args.out.open("w", newline="", encoding="utf-8") if args.out else sys.stdout
    try:
        if args.format == "json":
            json.dump(records, out, indent=1)
            out.write("\n")
        else:
            write_csv(records, out)
    finally:
        if args.out:
            out.close()
    return 0
