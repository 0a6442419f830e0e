"""The flight log: fixes sent, tracks, events and status, appended as the flight goes.

Format (docs/formats.md): JSON lines.  The first line is a header
``{"kind": "header", "format": "landmark-companion-flightlog", "version": 1, ...}``; every
other line is one record ``{"kind": ..., "t_us": ..., ...}``.  Each record is written to the
operating system as soon as it is logged (a crash of the process loses nothing) and the
file is fsync-ed at most ``fsync_interval_s`` apart (a power cut loses at most that much).
A reader skips a torn last line and counts it.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import threading
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from companion.errors import InputError

FORMAT = "landmark-companion-flightlog"
VERSION = 1

log = logging.getLogger(__name__)


class FlightLogWriter:
    """Append-only JSON-lines writer; safe to use from one thread at a time.

    Records go to the operating system as they are written (line-buffered); the fsync that
    bounds what a power cut loses runs every ``fsync_interval_s`` on a thread of its own,
    because an fsync can take milliseconds and the writer is the pipeline's event loop.
    """

    def __init__(self, path: Path, vehicle_id: str, fsync_interval_s: float = 1.0) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: TextIO = self.path.open("a", encoding="utf-8", buffering=1)
        self.records = 0
        self.syncs = 0
        self._emit({"kind": "header", "format": FORMAT, "version": VERSION,
                    "vehicle": vehicle_id, "started_unix_s": round(time.time(), 3)})
        self._closing = threading.Event()
        self._syncer = threading.Thread(target=self._sync_loop, args=(fsync_interval_s,),
                                        name="flightlog-fsync", daemon=True)
        self._syncer.start()

    def _emit(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, default=_plain, allow_nan=False) + "\n")

    def _sync_loop(self, interval_s: float) -> None:
        fd = self._file.fileno()
        while not self._closing.wait(interval_s):
            try:
                os.fsync(fd)  # what write() handed the OS (each record, line-buffered)
                self.syncs += 1
            except OSError as err:  # a full or vanished disk: the writes will say so too
                log.warning("flight log fsync failed: %s", err)

    def write(self, kind: str, t_us: int, **fields: Any) -> None:
        """Append one record of ``kind`` at time ``t_us`` (companion clock, microseconds)."""
        self._emit({"kind": kind, "t_us": int(t_us), **fields})
        self.records += 1

    def close(self) -> None:
        """Stop the fsync thread, flush and fsync; the file stays valid for readers."""
        self._closing.set()
        self._syncer.join()
        if not self._file.closed:
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()


def _plain(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"cannot log a {type(value).__name__}")


@dataclass(frozen=True)
class FlightLog:
    """A flight log read back: header, records, and lines that could not be read."""

    header: dict[str, Any]
    records: tuple[dict[str, Any], ...]
    torn_lines: int = 0
    kinds: Counter[str] = field(default_factory=Counter)


def read_flight_log(path: Path) -> FlightLog:
    """Read a flight log; a missing file or another format is an InputError (one line)."""
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: no such flight log") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read the flight log: {err}") from None
    parsed, torn = _parse(lines)
    if not parsed or parsed[0].get("format") != FORMAT:
        raise InputError(f"{path}: not a landmark-companion flight log (no header line)")
    header = parsed[0]
    if int(header.get("version", 0)) > VERSION:
        raise InputError(f"{path}: flight log version {header['version']} is newer than "
                         f"this program reads ({VERSION}); upgrade landmark-companion")
    records = tuple(r for r in parsed[1:] if r.get("kind") != "header")
    return FlightLog(header, records, torn, Counter(r.get("kind", "?") for r in records))


def _parse(lines: list[str]) -> tuple[list[dict[str, Any]], int]:
    parsed: list[dict[str, Any]] = []
    torn = 0
    for line in lines:
        try:
            value = json.loads(line)
        except ValueError:
            torn += 1
            continue
        if isinstance(value, dict):
            parsed.append(value)
        else:
            torn += 1
    return parsed, torn


def select(log: FlightLog, kind: str | None) -> Iterator[dict[str, Any]]:
    """The records of one kind (all when ``kind`` is None)."""
    return (r for r in log.records if kind is None or r.get("kind") == kind)


def write_csv(records: Iterable[dict[str, Any]], out: TextIO) -> int:
    """Records as CSV; nested values as JSON; columns = union of keys in first-seen order."""
    rows = list(records)
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    writer = csv.DictWriter(out, fieldnames=list(columns))
    writer.writeheader()
    for row in rows:
        writer.writerow({k: json.dumps(v) if isinstance(v, dict | list) else v
                         for k, v in row.items()})
    return len(rows)
