"""The flight log survives crashes and reads back; `companion log` shows and exports it."""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from companion.errors import InputError
from companion.flightlog import FlightLogWriter, read_flight_log, select, write_csv

ROOT = Path(__file__).resolve().parents[1]


def test_round_trip_with_numpy_values(tmp_path: Path) -> None:
    import numpy as np

    path = tmp_path / "f.jsonl"
    log = FlightLogWriter(path, "v1")
    log.write("fix", 1_000, position_ned_m=np.array([1.0, 2.0, -3.0]), quality=0.9)
    log.write("event", 2_000, event="lost", landmark="a")
    log.close()
    back = read_flight_log(path)
    assert back.header["vehicle"] == "v1"
    assert [r["kind"] for r in back.records] == ["fix", "event"]
    assert back.records[0]["position_ned_m"] == [1.0, 2.0, -3.0]
    assert back.kinds == {"fix": 1, "event": 1}
    assert [r["landmark"] for r in select(back, "event")] == ["a"]


def test_nan_is_refused_rather_than_written(tmp_path: Path) -> None:
    log = FlightLogWriter(tmp_path / "f.jsonl", "v1")
    with pytest.raises(ValueError):
        log.write("fix", 1, x=float("nan"))
    log.close()


def test_torn_last_line_is_skipped_and_counted(tmp_path: Path) -> None:
    path = tmp_path / "f.jsonl"
    log = FlightLogWriter(path, "v1")
    log.write("fix", 1)
    log.close()
    with path.open("a") as f:
        f.write('{"kind": "fix", "t_')
    back = read_flight_log(path)
    assert len(back.records) == 1
    assert back.torn_lines == 1


def test_killed_writer_loses_nothing_it_logged(tmp_path: Path) -> None:
    """SIGKILL right after a record is logged: every record already written is on disk."""
    path = tmp_path / "f.jsonl"
    script = (
        "import sys, time\n"
        "from pathlib import Path\n"
        "from companion.flightlog import FlightLogWriter\n"
        f"log = FlightLogWriter(Path({str(path)!r}), 'v1', fsync_interval_s=5.0)\n"
        "for i in range(200):\n"
        "    log.write('fix', i, n=i)\n"
        "print('logged', flush=True)\n"
        "time.sleep(60)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "logged"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    back = read_flight_log(path)
    assert [r["n"] for r in back.records] == list(range(200))


@pytest.mark.parametrize(("content", "message"), [
    (None, "no such flight log"),
    ('{"hello": 1}\n', "not a landmark-companion flight log"),
    ('{"kind": "header", "format": "landmark-companion-flightlog", "version": 9}\n',
     "version 9 is newer"),
])
def test_bad_files_are_one_line_errors(tmp_path: Path, content: str | None, message: str) -> None:
    path = tmp_path / "x.jsonl"
    if content is not None:
        path.write_text(content)
    with pytest.raises(InputError, match=message):
        read_flight_log(path)


def test_csv_has_the_union_of_columns() -> None:
    out = io.StringIO()
    n = write_csv([{"kind": "fix", "a": 1}, {"kind": "fix", "b": [1, 2]}], out)
    assert n == 2
    rows = list(csv.DictReader(io.StringIO(out.getvalue())))
    assert rows[0] == {"kind": "fix", "a": "1", "b": ""}
    assert json.loads(rows[1]["b"]) == [1, 2]


def test_cli_show_and_export(tmp_path: Path) -> None:
    path = tmp_path / "f.jsonl"
    log = FlightLogWriter(path, "v9")
    for i in range(5):
        log.write("fix", i * 1_000_000, n=i)
    log.write("event", 5_000_000, event="stop")
    log.close()

    def companion(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "companion", *args], cwd=ROOT,
                              capture_output=True, text=True, timeout=60, check=False)

    shown = companion("log", "show", str(path), "--tail", "2")
    assert shown.returncode == 0, shown.stderr
    assert "vehicle v9, 6 records over 5.0 s" in shown.stdout
    assert "event 1, fix 5" in shown.stdout
    assert shown.stdout.strip().splitlines()[-1] == json.dumps(
        {"kind": "event", "t_us": 5_000_000, "event": "stop"})
    out = tmp_path / "fixes.json"
    exported = companion("log", "export", str(path), "--kind", "fix", "--format", "json",
                         "--out", str(out))
    assert exported.returncode == 0, exported.stderr
    assert [r["n"] for r in json.loads(out.read_text())] == [0, 1, 2, 3, 4]
    missing = companion("log", "show", str(tmp_path / "none.jsonl"))
    assert missing.returncode == 2
    assert missing.stderr.strip() == f"{tmp_path / 'none.jsonl'}: no such flight log"


def test_fsync_runs_on_its_own_thread_and_close_leaves_none(tmp_path: Path) -> None:
    """The periodic fsync (power-cut bound) runs off the writer's thread -- the writer is
    the pipeline's event loop -- and closing stops that thread."""
    import threading
    import time

    log = FlightLogWriter(tmp_path / "f.jsonl", "v1", fsync_interval_s=0.02)
    log.write("fix", 1)
    deadline = time.monotonic() + 5.0
    while log.syncs < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert log.syncs >= 2
    assert any(t.name == "flightlog-fsync" for t in threading.enumerate())
    log.close()
    assert not any(t.name == "flightlog-fsync" for t in threading.enumerate())
