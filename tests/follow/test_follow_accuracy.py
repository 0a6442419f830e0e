"""Follow mode is as accurate as the scripted camera: the same flight, two ways.

Scripted: ``companion demo``'s flight (the camera renders the scenario's trajectory).
Follow: the fake autopilot flies the same trajectory and streams SIM_STATE/SIMSTATE; the
camera renders from that telemetry, interpolated, on the companion's clock.  Both compare
every fix with the scripted truth at the fix's time; follow mode may not be worse than
1.5x the scripted RMSE + 2 cm (telemetry is degE7-quantised and arrives at ~40 Hz).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from companion.app import Frame, FrameResult
from companion.autopilot import AttitudeHistory
from companion.demo import map_landmarks, run_demo
from companion.landmarks.geodesy import LocalFrame
from companion.runtime import PracticalMap, bridge_for, fly, perception_for
from companion.settings import Settings, load_settings
from companion.sim.follow import FollowCameraSource, command_sender
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from tracker.pose.types import PoseFix

SECONDS = 12.0


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return load_settings(sets=["monitor.enabled=false", f'flightlog.dir="{tmp_path}"'])


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

    class Recorder:
        def __init__(self, attitude: AttitudeHistory) -> None:
            self.perception = perception_for(settings, sim.scenario.camera, pmap, attitude)

        def process(self, frame: Frame) -> FrameResult:
            result = self.perception.process(frame)
            if isinstance(result.fix, PoseFix):
                truth = sim.state_at((frame.t_us * 1000 - fake.start_ns) / 1e9)
                errors.append(math.dist(result.fix.position_ned_m, truth.position_ned_m))
            return result

    try:
        app = await fly(settings, source, bridge, Recorder, landmarks, seconds=seconds,
                        prefix="follow")
    finally:
        await fake.stop()
    assert source.failure is None
    rmse = float(np.sqrt(np.mean(np.square(errors)))) if errors else None
    return {"fixes": len(errors), "frames": app.counters.frames, "position_rmse_m": rmse,
            "accepted": len(fake.accepted()), "sent": app.counters.fixes_sent,
            "refused": app.counters.fixes_refused, "bridge": bridge.stats()["vision"]}


async def test_follow_mode_fixes_match_the_truth_like_the_scripted_camera(
        settings: Settings) -> None:
    scripted = await run_demo(settings, "survey", SECONDS)
    follow = await follow_flight(settings, "survey", SECONDS)
    print(f"\nscripted: {scripted['fixes_sent']} fixes, RMSE {scripted['position_rmse_m']} m; "
          f"follow: {follow['fixes']} fixes, RMSE {follow['position_rmse_m']:.4f} m, "
          f"{follow['accepted']}/{follow['sent']} accepted by the fake autopilot "
          f"(refused by the bridge: {follow['bridge']})")
    assert scripted["position_rmse_m"] is not None
    assert follow["fixes"] >= 10, "too few follow-mode fixes for an RMSE"
    assert follow["position_rmse_m"] <= 1.5 * scripted["position_rmse_m"] + 0.02
    assert follow["accepted"] >= 0.8 * follow["sent"]
