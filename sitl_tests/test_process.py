"""The ``companion`` process itself: SIGTERM mid-flight, bad configuration, no landmark map.

These run the real console entry point (``python -m companion``) as a child process, against
the fake autopilot running in the test on UDP loopback.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from pathlib import Path

import pytest

from companion.flightlog import read_flight_log
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig
from sitl_tests.harness import SitlAutopilot
from testsupport.flightconfig import run_config as harness_run_config

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "config" / "landmarks.geojson"


def run_config(tmp: Path, port: int, map_path: Path = MAP, extra: str = "") -> Path:
    """A ``--config`` file for ``companion run``: the hover scenario, the fake on ``port``."""
    return harness_run_config(tmp, port, map_path=map_path,
                              extra="[monitor]\nenabled = false\n" + extra)


async def companion(*args: str, cwd: Path) -> asyncio.subprocess.Process:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return await asyncio.create_subprocess_exec(
        sys.executable, "-m", "companion", *args, cwd=cwd, env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)


async def test_sigterm_mid_flight(tmp_path: Path) -> None:
    """SIGTERM while fixes are flowing: exit 143 (128 + SIGTERM) within 10 s, and the flight
    log holds every fix the autopilot received, ends with the ``stopped`` event and has no
    torn line."""
    sim = Simulator(load_scenario("hover"))
    async with SitlAutopilot(FakeAutopilotConfig(), truth=sim.truth_fn) as fake:
        proc = await companion("--config", str(run_config(tmp_path, fake.local_port)), "run",
                               cwd=tmp_path)
        try:
            for _ in range(600):  # start-up (imports, first render) included: <= 30 s
                if len(fake.accepted()) >= 30 or proc.returncode is not None:
                    break
                await asyncio.sleep(0.05)
            assert len(fake.accepted()) >= 30, "no fixes flowing before the SIGTERM"
            proc.send_signal(signal.SIGTERM)
            _, err = await asyncio.wait_for(proc.communicate(), 10.0)
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
        await asyncio.sleep(0.2)  # let the last datagrams in
    assert proc.returncode == 143, err.decode()[-2000:]  # stopped by SIGTERM: 128 + 15
    assert b"Traceback" not in err
    logs = list((tmp_path / "logs").glob("run-*.jsonl"))
    assert len(logs) == 1
    log = read_flight_log(logs[0])
    assert log.torn_lines == 0
    events = [r.get("event") for r in log.records if r["kind"] == "event"]
    assert events[-1] == "stopped", events[-5:]
    assert log.records[-1]["kind"] == "status"
    # nothing lost: every fix that reached the autopilot is in the log, and no more
    assert log.kinds["fix"] == len(fake.vision), (log.kinds["fix"], len(fake.vision))
    print(f"SIGTERM after {len(fake.vision)} fixes: exit 143, {len(log.records)} log records")


@pytest.mark.parametrize(("extra", "expected"), [
    ("[tracker.filter]\nparticles = \"twenty\"", "tracker.filter.particles: expected an integer"),
    ("[mavlink]\nrate_hz = 500.0", "mavlink.rate_hz"),
    ("[vehicle]\nprofile = \"inav\"", "vehicle.profile"),
    ("[nonsense]\nkey = 1", "nonsense"),
    ("[source\nkind = ", "invalid TOML"),
])
async def test_bad_configuration(tmp_path: Path, extra: str, expected: str) -> None:
    """A bad configuration file: exit status 2, one line naming the key, no traceback, no
    flight started (no flight log)."""
    bad = tmp_path / "bad.toml"
    bad.write_text(extra + "\n", encoding="utf-8")
    proc = await companion("--config", str(bad), "run", cwd=tmp_path)
    _, err = await asyncio.wait_for(proc.communicate(), 30.0)
    lines = err.decode().strip().splitlines()
    assert proc.returncode == 2, err.decode()
    assert len(lines) == 1 and expected in lines[0], lines
    assert not (tmp_path / "flightlogs").exists()


@pytest.mark.parametrize("problem", ["missing", "not_json", "empty_features"])
async def test_missing_or_broken_landmark_map(tmp_path: Path, problem: str) -> None:
    """No landmark map, or one that is not GeoJSON: exit 2 with one line naming the file,
    before any MAVLink is sent."""
    map_path = tmp_path / "landmarks.geojson"
    if problem == "not_json":
        map_path.write_text("{ this is not json", encoding="utf-8")
    elif problem == "empty_features":
        map_path.write_text('{"type": "FeatureCollection"}', encoding="utf-8")
    async with SitlAutopilot(FakeAutopilotConfig()) as fake:
        proc = await companion("--config", str(run_config(tmp_path, fake.local_port, map_path)),
                               "run", "--seconds", "5", cwd=tmp_path)
        _, err = await asyncio.wait_for(proc.communicate(), 30.0)
        heard = len(fake.heartbeats)
    lines = err.decode().strip().splitlines()
    assert proc.returncode == 2, err.decode()
    assert len(lines) == 1 and str(map_path) in lines[0], lines
    assert "Traceback" not in err.decode()
    assert heard == 0, "the companion talked to the autopilot without a map"
