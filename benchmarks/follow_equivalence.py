"""Follow mode against the scripted camera, both flown live: the same flight, two ways.

Run: ``PYTHONPATH=. python benchmarks/follow_equivalence.py [--seconds 12] [--fps 15]``.

Scripted: ``companion demo``'s flight (the camera renders the scenario's trajectory).
Follow: the fake autopilot flies the same trajectory and streams SIM_STATE/SIMSTATE; the
camera renders from that telemetry, interpolated, on the companion's clock.  Both compare
every fix with the scripted truth at the fix's time.  Live flights depend on the machine's
load (frames dropped, fixes too old), so this prints numbers; the deterministic proof is
``tests/follow/test_follow_equivalence.py``.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from companion.app import Frame, FrameResult, ResultObserver
from companion.demo import map_landmarks, run_demo
from companion.follow import FollowCameraSource, command_sender
from companion.landmarks.geodesy import LocalFrame
from companion.runtime import CompanionFlight, PracticalMap, bridge_for
from companion.settings import SIM_LAYERS, Settings, load_settings
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from tracker.pose.types import PoseFix

SURVEY = Path(__file__).resolve().parents[1] / "config" / "scenarios" / "survey.toml"


def scenario_at(fps: float, folder: Path) -> str:
    """The survey scenario at ``fps`` frames per second (a file: run_demo takes a file)."""
    text = SURVEY.read_text().replace("fps = 30.0", f"fps = {fps}")
    text = text.replace('landmarks = "../landmarks.geojson"',
                        f'landmarks = "{SURVEY.parent.parent / "landmarks.geojson"}"')
    path = folder / "survey.toml"
    path.write_text(text)
    return str(path)


async def follow_flight(settings: Settings, scenario: str, seconds: float) -> dict[str, Any]:
    """The follow-mode flight in-process; returns the fixes' RMSE against the truth."""
    sim = Simulator(replace(load_scenario(scenario), seconds=seconds))
    landmarks, references = map_landmarks(sim)
    o = sim.scenario.origin
    local = LocalFrame(o.lat, o.lon, o.alt_m)
    pmap = PracticalMap(tuple(landmarks), references, local)
    profile = settings.vehicle.profile
    fake = FakeAutopilot(FakeAutopilotConfig(profile=profile), truth=sim.truth_fn)
    await fake.start()
    bridge = bridge_for(settings, endpoint=f"udpout:127.0.0.1:{fake.local_port}",
                        origin_lat_deg=o.lat, origin_lon_deg=o.lon, origin_alt_m=o.alt_m,
                        set_origin=True)
    source = FollowCameraSource(sim, bridge, local, profile, request=command_sender(bridge))
    errors: list[float] = []

    class Recorder(ResultObserver):
        def on_result(self, frame: Frame, result: FrameResult) -> None:
            if isinstance(result.fix, PoseFix):
                truth = sim.state_at((frame.t_us * 1000 - fake.start_ns) / 1e9)
                errors.append(math.dist(result.fix.position_ned_m, truth.position_ned_m))

    flight = CompanionFlight(settings, source, bridge, pmap, sim.scenario.camera,
                             prefix="follow")
    flight.observe(Recorder())
    try:
        app = await flight.run(seconds)
    finally:
        await fake.stop()
    assert source.failure is None
    rmse = float(np.sqrt(np.mean(np.square(errors)))) if errors else None
    return {"fixes": len(errors), "frames": app.counters.frames, "position_rmse_m": rmse,
            "accepted": len(fake.accepted()), "sent": app.counters.fixes_sent,
            "refused": app.counters.fixes_refused, "bridge": bridge.stats()["vision"]}


async def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--fps", type=float, default=15.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        settings = load_settings(shipped=SIM_LAYERS,
                                 sets=["monitor.enabled=false", f'flightlog.dir="{tmp}"'])
        scenario = scenario_at(args.fps, Path(tmp))
        scripted = await run_demo(settings, scenario, args.seconds)
        follow = await follow_flight(settings, scenario, args.seconds)
    print(f"scripted: {scripted['fixes_sent']} fixes sent, RMSE "
          f"{scripted['position_rmse_m']} m")
    print(f"follow:   {follow['fixes']} fixes solved ({follow['sent']} sent, "
          f"{follow['accepted']} accepted by the fake autopilot; bridge {follow['bridge']}), "
          f"RMSE {follow['position_rmse_m']:.4f} m")


if __name__ == "__main__":
    asyncio.run(main())
