"""``dev.py test``: the long real-time flights run beside the rest, and either failing fails
the suite (docs/testing.md, "CI's budget")."""

from __future__ import annotations

import os
import stat
import time
from pathlib import Path

import pytest

import conftest
import dev


def test_the_realtime_flights_are_slow_and_named_by_file_or_test() -> None:
    for prefix in conftest.REALTIME:
        assert conftest.is_slow(prefix)  # the fast suite leaves them out too
    assert conftest.is_realtime(
        "sitl_tests/test_fly_strict.py::test_three_laps_against_the_strict_fake[3]")
    assert conftest.is_realtime("sitl_tests/test_soak.py::test_soak_short")
    assert not conftest.is_realtime(
        "sitl_tests/test_fly_strict.py::test_an_8s_outage_in_flight_lands_and_stops_fly")
    assert not conftest.is_realtime("sitl_tests/test_soak.py_other::test_x")


def fake_python(tmp_path: Path, flights: int, rest: int, sleep: float = 0.6) -> Path:
    """A stand-in for the venv's python: ``-m pytest -m realtime ...`` writes its pid,
    prints a line, sleeps ``sleep`` s, prints another and exits ``flights``; any other
    pytest, ``rest``."""
    script = tmp_path / "python"
    script.write_text(f"""#!/bin/sh
if [ "$4" = "realtime" ]; then
  echo $$ > "{tmp_path}/flights.pid"; echo "flights: $*"; sleep {sleep}; echo "flights end"
  exit {flights}
fi
echo "rest: $*"; exit {rest}
""")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script


@pytest.mark.parametrize(("flights", "rest", "status", "said"), [
    (0, 0, 0, None),
    (1, 0, 1, "failed: the real-time flights (1)"),
    (0, 2, 2, "failed: the rest (2)"),
    (5, 0, 1, "failed: the real-time flights (1)"),  # none collected is a failure
    (1, 3, 3, "failed: the rest (3), the real-time flights (1)"),
])
def test_both_pytests_run_and_either_failing_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str],
        flights: int, rest: int, status: int, said: str | None) -> None:
    monkeypatch.setattr(dev, "PY", fake_python(tmp_path, flights, rest))
    monkeypatch.setattr(dev, "FLIGHTS_LOG", dev.ROOT / "test-output" / f"t-{tmp_path.name}.log")
    try:
        assert dev.pytest_beside_flights() == status
        out = capfd.readouterr().out
    finally:
        dev.FLIGHTS_LOG.unlink(missing_ok=True)
    assert "rest: -m pytest -m not realtime" in out
    # the flights' output, written to the log while the rest ran, is printed after it and
    # followed until they end
    assert out.index("rest: -m pytest") < out.index("flights: -m pytest -m realtime") \
        < out.index("flights end")
    assert (said in out) if said else ("failed" not in out)


def test_an_interrupted_suite_leaves_no_flight_running(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dev, "PY", fake_python(tmp_path, 0, 0, sleep=60))
    monkeypatch.setattr(dev, "FLIGHTS_LOG", dev.ROOT / "test-output" / f"t-{tmp_path.name}.log")

    def interrupted(*_cmd: object, check: bool = True) -> int:
        while not (tmp_path / "flights.pid").exists():  # the flights have started
            time.sleep(0.05)
        raise KeyboardInterrupt

    monkeypatch.setattr(dev, "run", interrupted)
    try:
        with pytest.raises(KeyboardInterrupt):
            dev.pytest_beside_flights()
    finally:
        dev.FLIGHTS_LOG.unlink(missing_ok=True)
    pid = int((tmp_path / "flights.pid").read_text())
    with pytest.raises(ProcessLookupError):  # terminated and reaped
        os.kill(pid, 0)
