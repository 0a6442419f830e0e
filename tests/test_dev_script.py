"""``dev.py test``: the long real-time flights run beside the rest, and either failing fails
the suite (docs/testing.md, "CI's budget")."""

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


def fake_python(tmp_path: Path, flights: int, rest: int, sleep: float = 0.6) -> Path:
    """A stand-in for the venv's python.  ``-m pytest -m realtime ...``: ignores SIGTERM (as
    a flight does, landing) and so does the child it starts (``sleep``), writes both pids,
    prints a line, waits for the child, prints another and exits ``flights``.  Any other
    pytest waits until the flights have started (they run at the same time), then prints a
    line and exits ``rest``.  Both print their scheduling priority (``nice``)."""
    pids = tmp_path / "flights.pid"
    script = tmp_path / "python"
    script.write_text(f"""#!/bin/sh
if [ "$4" = "realtime" ]; then
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


@pytest.mark.parametrize(("flights", "rest", "status", "said"), [
    (0, 0, 0, None),
    (1, 0, 1, "failed: the real-time flights (1)"),
    (0, 2, 2, "failed: the rest (2)"),
    (5, 0, 1, "failed: the real-time flights (1)"),  # none collected is a failure
    (0, 5, 1, "failed: the rest (1)"),
    (1, 3, 3, "failed: the rest (3), the real-time flights (1)"),
])
def test_both_pytests_run_at_once_and_either_failing_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str],
        flights: int, rest: int, status: int, said: str | None) -> None:
    monkeypatch.setattr(dev, "PY", fake_python(tmp_path, flights, rest))
    monkeypatch.setattr(dev, "FLIGHTS_LOG", dev.ROOT / "test-output" / f"t-{tmp_path.name}.log")
    try:
        assert dev.pytest_beside_flights() == status
        out = capfd.readouterr().out
    finally:
        dev.FLIGHTS_LOG.unlink(missing_ok=True)
    assert "rest: -m pytest -m not realtime" in out  # it saw the flights running
    # the flights' output, written to the log while the rest ran, is printed after it and
    # followed until they end; nothing of theirs is left running
    assert out.index("rest: -m pytest") < out.index("flights: -m pytest -m realtime") \
        < out.index("flights end")
    assert (said in out) if said else ("failed" not in out)
    # the rest yields the cores to the flights, which are judged on their timing
    niceness = {who: int(out.split(f"{who} at nice ", 1)[1].split()[0])
                for who in ("rest", "flights")}
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

    def interrupted(*_cmd: object, check: bool = True, nice: int = 0) -> int:
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
