"""``--fly`` watches the vehicle: it stops commanding on a disarm, a mode change or a failsafe
(issue 19), naming why with the autopilot's last STATUSTEXT, whichever the profile."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import pytest

from companion.errors import EXIT_FLIGHT_ABORTED
from companion.square import (
    ARDUCOPTER_GUIDED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    MAV_STATE_CRITICAL,
    FlightAbortedError,
    SquareFlight,
    SquarePlan,
)

MAV_STATE_ACTIVE = 4
PX4_OFFBOARD = 6 << 16
PX4_AUTO_LAND = (4 << 16) | (6 << 24)


@dataclass
class _Vehicle:
    """What ``latest`` reads: the last HEARTBEAT and STATUSTEXT, changed by the test."""

    custom_mode: int
    armed: bool = True
    system_status: int = MAV_STATE_ACTIVE
    text: str | None = None

    def latest(self, name: str) -> Any:
        if name == "HEARTBEAT":
            base = MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
            return SimpleNamespace(value=SimpleNamespace(
                base_mode=base | 1, custom_mode=self.custom_mode,
                system_status=self.system_status))
        if name == "STATUSTEXT" and self.text is not None:
            return SimpleNamespace(value=SimpleNamespace(text=self.text))
        return None


class _Link:
    autopilot_sysid = 1

    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []

    def send(self, name: str, **fields: Any) -> None:
        self.sent.append((name, fields))


PLAN = SquarePlan(side_m=2.0, altitude_m=1.0, leg_s=5.0, loops=1, climb_m_s=5.0,
                  settle_s=0.0, setpoint_rate_hz=20.0)


async def _fly_until(vehicle: _Vehicle, profile: str, change: dict[str, Any],
                     text: str) -> tuple[FlightAbortedError, _Link, int]:
    """Fly; after 0.3 s apply ``change`` to the vehicle; the abort and the sends before it."""
    link = _Link()
    flight = SquareFlight(link, vehicle.latest, profile, PLAN)
    task = asyncio.create_task(flight.run())
    await asyncio.sleep(0.3)
    assert not task.done(), "the flight stopped before anything changed"
    for key, value in change.items():
        setattr(vehicle, key, value)
    vehicle.text = text
    before = len(link.sent)
    with pytest.raises(FlightAbortedError) as info:
        await asyncio.wait_for(task, 2.0)
    assert flight.aborted is not None
    return info.value, link, before


@pytest.mark.parametrize(("profile", "mode", "change", "why"), [
    ("ardupilot", ARDUCOPTER_GUIDED, {"armed": False}, "the vehicle disarmed"),
    ("ardupilot", ARDUCOPTER_GUIDED, {"custom_mode": 9},
     "the autopilot changed mode to LAND (was GUIDED)"),
    ("ardupilot", ARDUCOPTER_GUIDED, {"system_status": MAV_STATE_CRITICAL},
     "the autopilot reports a failsafe (MAV_STATE_CRITICAL)"),
    ("px4", PX4_OFFBOARD, {"custom_mode": PX4_AUTO_LAND},
     "the autopilot changed mode to AUTO.LAND (was OFFBOARD)"),
    ("px4", PX4_OFFBOARD, {"armed": False}, "the vehicle disarmed"),
])
async def test_fly_stops_commanding_and_says_why(
    profile: str, mode: int, change: dict[str, Any], why: str
) -> None:
    vehicle = _Vehicle(custom_mode=mode)
    err, link, before = await _fly_until(vehicle, profile, change, "the autopilot's words")
    assert str(err) == f"--fly stopped commanding: {why}; autopilot: \"the autopilot's words\""
    assert err.exit_status == EXIT_FLIGHT_ABORTED != 0
    await asyncio.sleep(0.2)
    assert len(link.sent) <= before + 1, "it went on commanding after the change"


async def test_fly_keeps_flying_while_nothing_changes() -> None:
    """The same vehicle left alone: setpoints go on, nothing is raised (the check can pass)."""
    vehicle = _Vehicle(custom_mode=ARDUCOPTER_GUIDED)
    link = _Link()
    task = asyncio.create_task(SquareFlight(link, vehicle.latest, "ardupilot", PLAN).run())
    await asyncio.sleep(0.6)
    n = len(link.sent)
    await asyncio.sleep(0.6)
    assert not task.done()
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert len(link.sent) > n
