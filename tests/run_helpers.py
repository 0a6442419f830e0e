"""Shared by the tests that start ``companion run``: a recorded stream written by
``companion synth`` (with its landmark map and appearance images), a map of a few of its
landmarks, and the flight log's records."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from companion.cli import main
from companion.core.map_file import read_map, write_map
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.vehicle import TruthFn

SIM_LAYER = Path(__file__).resolve().parents[1] / "config" / "sim.toml"

#: The survey world's origin (config/landmarks.geojson), the EKF origin of these runs.
ORIGIN = ("47.3769", "8.5417", "408.0")


def synth(out: Path, seconds: float = 3.0, scenario: str = "survey") -> Path:
    """A recorded stream of ``scenario`` in ``out`` (and its ``landmarks.geojson``)."""
    assert main(["synth", "--scenario", scenario, "--seconds", str(seconds),
                 "--out", str(out)]) == 0
    return out


def free_udp_port() -> int:
    """A loopback UDP port nobody listens on (bound, then released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def write_subset(stream: Path, out: Path, keep: dict[str, dict[str, Any]]) -> Path:
    """A map of the stream's landmarks named in ``keep`` (id -> fields to change, e.g.
    ``{"appearance": None}`` or ``{"status": "candidate"}``)."""
    import dataclasses

    records = [dataclasses.replace(lm, **keep[lm.id])
               for lm in read_map(stream / "landmarks.geojson") if lm.id in keep]
    write_map(out, records)
    return out


def run_args(tmp_path: Path, stream: Path, port: int, *extra: str) -> list[str]:
    """``companion run`` on ``stream`` with the survey origin, monitoring off, the flight
    log in ``tmp_path``, the link to ``udpout:127.0.0.1:port`` and the database's map
    (``extra`` comes last, so it may set ``landmarks.map_path``).  The recordings are the
    simulator's, so the simulator's layer of defaults (config/sim.toml) is read."""
    lat, lon, alt = ORIGIN
    return ["run", "--config", str(SIM_LAYER), "--set", 'source.kind="auto"',
            "--set", f'source.spec="stream:{stream}"',
            "--set", f"mavlink.origin_lat_deg={lat}", "--set", f"mavlink.origin_lon_deg={lon}",
            "--set", f"mavlink.origin_alt_m={alt}", "--set", "monitor.enabled=false",
            "--set", f'flightlog.dir="{tmp_path / "logs"}"',
            "--set", f'mavlink.endpoint="udpout:127.0.0.1:{port}"',
            "--set", 'landmarks.map_path=""', *extra]


def flight_records(logs: Path) -> list[dict[str, Any]]:
    """Every record of the run flight logs in ``logs``, in order."""
    return [json.loads(line) for log in sorted(logs.glob("run-*.jsonl"))
            for line in log.read_text().splitlines()]


@contextmanager
def fake_flying(scenario: str, config: FakeAutopilotConfig | None = None
                ) -> Iterator[FakeAutopilot]:
    """The fake autopilot, on its own event loop in a thread (``companion run`` owns the
    main one), flying the scenario's trajectory from its start, on a free loopback port."""
    sim = Simulator(load_scenario(scenario))
    with fake_in_thread(config or FakeAutopilotConfig(endpoint="udpin:127.0.0.1:0"),
                        sim.truth_fn) as fake:
        yield fake


@contextmanager
def fake_in_thread(config: FakeAutopilotConfig, truth: TruthFn) -> Iterator[FakeAutopilot]:
    """The fake autopilot flying ``truth`` on its own event loop in a thread, until the
    ``with`` block ends."""
    with fake_and_loop(config, truth) as (fake, _loop):
        yield fake


@contextmanager
def fake_and_loop(config: FakeAutopilotConfig, truth: TruthFn | None = None
                  ) -> Iterator[tuple[FakeAutopilot, asyncio.AbstractEventLoop]]:
    """The fake autopilot on its own event loop in a thread (``companion run`` owns the
    main one), and that loop (to call the fake's fault methods on it)."""
    loop = asyncio.new_event_loop()
    started = threading.Event()
    box: list[FakeAutopilot] = []

    async def serve() -> None:
        fake = FakeAutopilot(config, truth=truth)
        await fake.start()
        box.append(fake)
        started.set()
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            pass
        finally:
            await fake.stop()

    thread = threading.Thread(target=loop.run_until_complete, args=(serve(),), daemon=True)
    thread.start()
    assert started.wait(5.0), "fake autopilot did not start"
    try:
        yield box[0], loop
    finally:
        def cancel_all() -> None:
            for t in asyncio.all_tasks(loop):
                t.cancel()
        loop.call_soon_threadsafe(cancel_all)
        thread.join(5.0)
