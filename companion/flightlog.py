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
from typing import Any, BinaryIO, TextIO

from companion.errors import InputError

FORMAT = "landmark-companion-flightlog"
VERSION = 1

log = logging.getLogger(__name__)


class FlightLogWriter:
    """Append-only JSON-lines writer; safe to use from one thread at a time.

    Each record goes to the operating system in one ``write`` as it is logged; the fsync that
    bounds what a power cut loses runs every ``fsync_interval_s`` on a thread of its own,
    because an fsync can take milliseconds and the writer is the pipeline's event loop.

    The file is created, never appended to: when ``path`` exists (two runs started in the
    same second), ``-2``, ``-3`` ... is added to its name.  With ``max_file_bytes`` > 0 the
    log rotates: a record that would take the file past the limit starts the next part
    (``NAME.2.jsonl``, ``NAME.3.jsonl`` ...), which begins with its own header.  A write or
    fsync that fails (full disk, file-size limit, vanished disk) stops the log with one
    warning: the flight goes on, later records are counted in :attr:`dropped` and not
    written, and :meth:`close` never raises.
    """

    def __init__(self, path: Path, vehicle_id: str, fsync_interval_s: float = 1.0,
                 max_file_bytes: int = 0) -> None:
        self.vehicle_id = vehicle_id
        self.max_file_bytes = max_file_bytes
        self.records = 0
        self.syncs = 0
        self.dropped = 0
        #: Why the log stopped (one line), or None while it is written.
        self.failure: str | None = None
        self._lock = threading.Lock()  # the fsync thread and a rotation share the file
        self.paths: list[Path] = []
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self._base = _create_unique(Path(path))
        self._file: BinaryIO | None = None
        self._bytes = 0
        self._start_part(self._base)
        self._closing = threading.Event()
        self._syncer = threading.Thread(target=self._sync_loop, args=(fsync_interval_s,),
                                        name="flightlog-fsync", daemon=True)
        self._syncer.start()

    @property
    def path(self) -> Path:
        """The file being written (the latest part)."""
        return self.paths[-1]

    def _start_part(self, file: BinaryIO) -> None:
        self._file = file
        self._bytes = 0
        self.paths.append(Path(file.name))
        header: dict[str, Any] = {"kind": "header", "format": FORMAT, "version": VERSION,
                                  "vehicle": self.vehicle_id,
                                  "started_unix_s": round(time.time(), 3)}
        if len(self.paths) > 1:
            header.update(part=len(self.paths), previous=self.paths[-2].name)
        self._write_line(json.dumps(header).encode() + b"\n")

    def _rotate(self) -> None:
        assert self._file is not None
        with self._lock:
            _sync_and_close(self._file)
            base = self.paths[0]
            name = f"{base.name.removesuffix('.jsonl')}.{len(self.paths) + 1}.jsonl"
            self._file = None
        self._start_part(_create_unique(base.with_name(name)))

    def _write_line(self, line: bytes) -> None:
        assert self._file is not None
        view = memoryview(line)
        while view:  # a regular file may take part of it when the disk fills up
            written = self._file.write(view)
            view = view[written or 0:]
        self._bytes += len(line)

    def _sync_loop(self, interval_s: float) -> None:
        while not self._closing.wait(interval_s):
            with self._lock:
                if self._file is None or self.failure is not None:
                    continue
                try:
                    os.fsync(self._file.fileno())  # what write() handed the OS
                    self.syncs += 1
                except OSError as err:  # a full or vanished disk
                    self._stop(err)

    def write(self, kind: str, t_us: int, **fields: Any) -> None:
        """Append one record of ``kind`` at time ``t_us`` (companion clock, microseconds).

        NaN or infinity is a ``ValueError`` (nothing written); a failing disk is not an
        error here (see the class doc)."""
        line = json.dumps({"kind": kind, "t_us": int(t_us), **fields}, default=_plain,
                          allow_nan=False).encode() + b"\n"
        if self.failure is not None:
            self.dropped += 1
            return
        try:
            if self.max_file_bytes and self._bytes + len(line) > self.max_file_bytes:
                self._rotate()
            self._write_line(line)
        except OSError as err:
            self.dropped += 1
            with self._lock:
                self._stop(err)
            return
        self.records += 1

    def _stop(self, err: OSError) -> None:
        """Stop writing for good, with one warning (the caller holds the lock)."""
        if self.failure is not None:
            return
        self.failure = f"{self.path}: {err.strerror or err}"
        log.warning("flight log stopped: %s; the flight goes on without it (records from "
                    "here on are counted, not written)", self.failure)

    def close(self) -> None:
        """Stop the fsync thread, fsync and close; never raises (the file stays valid for
        readers: at worst its last line is torn, which a reader skips).  Idempotent."""
        if self._closing.is_set():
            return
        self._closing.set()
        self._syncer.join()
        with self._lock:
            if self._file is not None:
                try:
                    _sync_and_close(self._file)
                except OSError as err:
                    self._stop(err)
                finally:
                    self._file = None
        if self.dropped:
            log.warning("flight log: %d records not written (%s)", self.dropped, self.failure)


def _create_unique(path: Path) -> BinaryIO:
    """Create ``path`` exclusively (unbuffered); if it exists, ``STEM-2.jsonl``, ``-3``..."""
    suffix = ".jsonl" if path.name.endswith(".jsonl") else ""
    stem = path.name.removesuffix(suffix) if suffix else path.name
    for n in range(1, 10_000):
        candidate = path if n == 1 else path.with_name(f"{stem}-{n}{suffix}")
        try:
            return candidate.open("xb", buffering=0)
        except FileExistsError:
            continue
    raise FileExistsError(f"{path}: 10 000 flight logs of that name exist")


def _sync_and_close(file: BinaryIO) -> None:
    try:
        os.fsync(file.fileno())
    finally:
        file.close()


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
