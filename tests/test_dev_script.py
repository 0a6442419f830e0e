"""``dev.py test``: the flights marked ``alone`` fly first with nothing beside them, the
other long real-time flights run beside the rest, and any part failing fails the suite
(docs/testing.md, "CI's budget")."""

from __future__ import annotations

import stat
import time
from pathlib import Path

import pytest

import conftest
import dev


def test_the_realtime_flights_are_slow_and_named_by_folder_file_or_test(
        monkeypatch: pytest.MonkeyPatch) -> None:
    for prefix in conftest.REALTIME:
        assert conftest.is_slow(prefix)  # the fast suite leaves them out too
    assert conftest.is_realtime(
        "sitl_tests/test_fly_strict.py::test_three_laps_against_the_strict_fake[3]")
    assert conftest.is_realtime(
        "sitl_tests/test_mavlink_faults.py::test_corrupted_bytes_from_autopilot")
    assert not conftest.is_realtime("tests/test_demo.py::test_x")
    assert not conftest.is_realtime("sitl_tests_other/test_x.py::test_x")
    monkeypatch.setattr(conftest, "REALTIME", ("sitl_tests/test_soak.py",
                                               "sitl_tests/test_a.py::test_b"))
    assert conftest.is_realtime("sitl_tests/test_soak.py::test_soak_short")
    assert conftest.is_realtime("sitl_tests/test_a.py::test_b[1]")
    assert not conftest.is_realtime("sitl_tests/test_a.py::test_bc")
    assert not conftest.is_realtime("sitl_tests/test_soak.py_other::test_x")


def test_the_flights_alone_are_the_strict_square_and_realtime() -> None:
    square = "sitl_tests/test_fly_strict.py::test_three_laps_against_the_strict_fake"
    for prefix in conftest.ALONE:
        assert conftest.is_realtime(prefix)  # flown by the flights' pytest, never the rest's
    assert conftest.is_alone(f"{square}[4]")
    assert not conftest.is_alone(
        "sitl_tests/test_fly_strict.py::test_an_8s_outage_in_flight_lands_and_stops_fly[0-px4]")


def fake_python(tmp_path: Path, flights: int, rest: int, sleep: float = 0.6,
                alone: int = 0) -> Path:
    """A stand-in for the venv's python.  ``-m pytest -m "realtime and alone"``: refuses to
    run once another pytest has started, prints a line and exits ``alone``.
    ``-m pytest -m "realtime and not alone" ...``: refuses to run before the flights alone
    ended, ignores SIGTERM (as a flight does, landing) and so does the child it starts
    (``sleep``), writes both pids, prints a line, waits for the child, prints another and
    exits ``flights``.  Any other pytest refuses to run before the flights alone ended,
    waits until the flights have started (they run at the same time), then prints a line
    and exits ``rest``.  Each prints its scheduling priority (``nice``)."""
    pids = tmp_path / "flights.pid"
    alone_done = tmp_path / "alone.done"
    script = tmp_path / "python"
    script.write_text(f"""#!/bin/sh
if [ "$4" = "realtime and alone" ]; then
  [ -f "{pids}" ] && {{ echo "alone: the other flights had started"; exit 98; }}
  echo "alone: $*"
  echo "alone at nice $(nice)"
  sleep 0.2
  [ -f "{pids}" ] && {{ echo "alone: the other flights started beside"; exit 98; }}
  touch "{alone_done}"
  exit {alone}
fi
[ -f "{alone_done}" ] || {{ echo "$4: ran before the flights alone had ended"; exit 97; }}
if [ "$4" = "realtime and not alone" ]; then
  trap '' TERM
  sleep {sleep} &
  echo "$$ $!" > "{pids}.tmp" && mv "{pids}.tmp" "{pids}"
  echo "flights: $*"
  echo "flights at nice $(nice)"
  wait
  echo "flights end"
  exit {flights}
fi
i=0
while [ ! -f "{pids}" ] && [ $i -lt 200 ]; do sleep 0.05; i=$((i + 1)); done
[ -f "{pids}" ] || {{ echo "rest: the flights had not started"; exit 99; }}
echo "rest: $*"
echo "rest at nice $(nice)"
exit {rest}
""")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script


def running(pid: int) -> bool:
    """Is ``pid`` a live process (not gone, not a zombie waiting to be reaped)?"""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


@pytest.mark.parametrize(("alone", "flights", "rest", "status", "said"), [
    (0, 0, 0, 0, None),
    (0, 1, 0, 1, "failed: the real-time flights (1)"),
    (0, 0, 2, 2, "failed: the rest (2)"),
    (0, 5, 0, 1, "failed: the real-time flights (1)"),  # none collected is a failure
    (0, 0, 5, 1, "failed: the rest (1)"),
    (0, 1, 3, 3, "failed: the rest (3), the real-time flights (1)"),
    (1, 0, 0, 1, "failed: the flights alone (1)"),  # and the others still ran
    (5, 0, 0, 1, "failed: the flights alone (1)"),
    (4, 0, 2, 4, "failed: the flights alone (4), the rest (2)"),
])
def test_alone_first_then_both_pytests_at_once_and_any_failing_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str],
        alone: int, flights: int, rest: int, status: int, said: str | None) -> None:
    monkeypatch.setattr(dev, "PY", fake_python(tmp_path, flights, rest, alone=alone))
    monkeypatch.setattr(dev, "FLIGHTS_LOG", dev.ROOT / "test-output" / f"t-{tmp_path.name}.log")
    try:
        assert dev.pytest_beside_flights() == status
        out = capfd.readouterr().out
    finally:
        dev.FLIGHTS_LOG.unlink(missing_ok=True)
    assert "rest: -m pytest -m not realtime" in out  # it saw the flights running
    # the flights alone came first, on their own; the other flights' output, written to the
    # log while the rest ran, is printed after it and followed until they end; nothing of
    # theirs is left running
    assert "ran before" not in out and "started beside" not in out
    assert out.index("alone: -m pytest -m realtime and alone") < out.index("rest: -m pytest") \
        < out.index("flights: -m pytest -m realtime and not alone") < out.index("flights end")
    assert (said in out) if said else ("failed" not in out)
    # the rest yields the cores to the flights, which are judged on their timing
    niceness = {who: int(out.split(f"{who} at nice ", 1)[1].split()[0])
                for who in ("rest", "flights", "alone")}
    assert niceness["alone"] == niceness["flights"]
    assert dev.REST_NICE > 0  # (19 is the lowest priority: a niced suite's stand-ins cap)
    assert niceness["rest"] == min(niceness["flights"] + dev.REST_NICE, 19) > niceness["flights"]
    assert not any(running(int(pid)) for pid in (tmp_path / "flights.pid").read_text().split())


def test_an_interrupted_suite_leaves_no_flight_running(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C (or SIGTERM, which dev.py turns into the same unwinding) while the rest runs:
    the flights, which ignore SIGTERM as a landing flight does, and what they started are
    killed after the grace and reaped."""
    monkeypatch.setattr(dev, "PY", fake_python(tmp_path, 0, 0, sleep=60))
    monkeypatch.setattr(dev, "FLIGHTS_LOG", dev.ROOT / "test-output" / f"t-{tmp_path.name}.log")
    monkeypatch.setattr(dev, "STOP_GRACE_S", 0.3)
    pids = tmp_path / "flights.pid"

    flown_alone = dev.run

    def interrupted(*cmd: str | Path, check: bool = True, nice: int = 0) -> int:
        if f"{dev.REALTIME} and {dev.ALONE}" in cmd:  # the first part runs to its end
            return flown_alone(*cmd, check=check, nice=nice)
        deadline = time.monotonic() + 10.0
        while not pids.exists():  # the flights have started
            assert time.monotonic() < deadline, "the flights never started"
            time.sleep(0.05)
        raise KeyboardInterrupt

    monkeypatch.setattr(dev, "run", interrupted)
    started = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            dev.pytest_beside_flights()
    finally:
        dev.FLIGHTS_LOG.unlink(missing_ok=True)
    assert time.monotonic() - started < 10.0  # not the flights' 60 s
    leader, child = (int(p) for p in pids.read_text().split())
    assert not running(leader)
    deadline = time.monotonic() + 5.0  # the killed child's zombie is its new parent's to reap
    while running(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not running(child)
