"""Autopilot-side faults: a reboot and a link that goes down for 5 s."""

from __future__ import annotations

from companion.settings import Settings
from sitl_tests.harness import Flight, first_at_or_after, wait_until

MAV_CMD_DO_SET_GLOBAL_ORIGIN = 611


async def steady_fixes(flight: Flight, count: int = 10, timeout_s: float = 8.0) -> float:
    """Wait until the autopilot has fused ``count`` fixes and has its origin."""
    fake = flight.fake
    return await wait_until(
        flight, lambda: len(fake.accepted_times()) >= count and fake.origin is not None,
        timeout_s=timeout_s, what=f"{count} fused fixes and the EKF origin")


def origins_accepted(flight: Flight) -> int:
    return sum(1 for c in flight.fake.commands
               if c["command"] == MAV_CMD_DO_SET_GLOBAL_ORIGIN and c["result"] == 0)


async def test_autopilot_reboot(settings: Settings) -> None:
    """The autopilot reboots mid-flight (silent 1 s, then new boot time, no origin).

    Proves: the companion notices the reboot, sends the EKF origin again, and fixes are
    fused again within 2 s of the autopilot coming back; nothing stale is sent meanwhile.
    """
    silent_s = 1.0
    times: dict[str, float] = {}

    async def script(flight: Flight) -> None:
        await steady_fixes(flight)
        assert origins_accepted(flight) == 1
        times["reboot"] = flight.mark("reboot")
        flight.fake.reboot(silent_s)
        assert flight.fake.origin is None, "the reboot did not clear the origin"
        back = times["reboot"] + silent_s
        await wait_until(flight, lambda: flight.fake.origin is not None, timeout_s=silent_s + 2.0,
                         what="EKF origin set again after the reboot")
        times["origin"] = flight.flight_s()
        await wait_until(flight, lambda: first_at_or_after(flight.fake.accepted_times(), back)
                         is not None, timeout_s=silent_s + 2.0, what="fixes fused after reboot")

    flight = await Flight("hover", 12.0, settings).run(script)
    fake, back = flight.fake, times["reboot"] + silent_s
    assert fake.counters["reboots"] == 1
    assert flight.bridge.stats()["reboots"] == 1, "the companion did not detect the reboot"
    assert origins_accepted(flight) == 2, "the origin was not sent again"
    resumed = first_at_or_after(fake.accepted_times(), back)
    assert resumed is not None and resumed - back <= 2.0, (back, resumed)
    assert not flight.stale(), f"stale fixes: {flight.stale()[:3]}"
    # fixes keep coming to the end
    assert fake.accepted_times()[-1] > flight.seconds - 1.0
    print(f"reboot at {times['reboot']:.2f} s, back {back:.2f} s, origin again "
          f"{times['origin'] - back:.2f} s later, fixes {resumed - back:.2f} s later")


async def test_link_down_5s(settings: Settings) -> None:
    """Nothing passes either way for 5 s mid-flight.

    Proves: the companion sees the link go down (health ``link-down``) and back; its heartbeat
    and fused fixes resume within 1 s of the link's return; no burst of stale fixes follows
    (every fix's age is under ``mavlink.max_fix_age_ms``, at most one per camera frame).
    """
    down_s = 5.0
    times: dict[str, float] = {}
    states: set[str] = set()

    async def script(flight: Flight) -> None:
        await steady_fixes(flight)
        times["drop"] = flight.mark("link down 5 s")
        flight.fake.drop_link(down_s)
        assert flight.app is not None
        app = flight.app
        await wait_until(flight, lambda: not flight.bridge.link_up,
                         timeout_s=settings.mavlink.link_timeout_s + 1.0,
                         what="companion sees the link down")
        await wait_until(flight, lambda: app.state == "link-down", timeout_s=1.5,
                         what="health link-down")
        states.add(app.state)
        await wait_until(flight, lambda: flight.bridge.link_up, timeout_s=down_s + 1.0,
                         what="companion sees the link back")

    flight = await Flight("hover", 14.0, settings).run(script)
    fake = flight.fake
    back = times["drop"] + down_s
    assert fake.faults.counters.dropped_link_down > 0 and "link-down" in states
    beats = [h.arrival_s for h in fake.heartbeats]
    assert not [b for b in beats if times["drop"] + 0.05 < b < back - 0.05], "heartbeat in outage"
    hb = first_at_or_after(beats, back)
    assert hb is not None and hb - back <= 1.0, f"heartbeat {hb} after return at {back}"
    fused = first_at_or_after(fake.accepted_times(), back)
    assert fused is not None and fused - back <= 1.0, f"fix {fused} after return at {back}"
    after = [a for a in fake.arrivals if a.flight_s >= back]
    assert not flight.stale(back), f"stale fixes after the return: {flight.stale(back)[:3]}"
    first_second = [a for a in after if a.flight_s < back + 1.0]
    assert len(first_second) <= flight.sim.fps + 1, f"{len(first_second)} fixes in 1 s: burst"
    print(f"link back at {back:.2f} s: heartbeat +{hb - back:.2f} s, fix +{fused - back:.2f} s, "
          f"{len(first_second)} fixes in the first second, max age "
          f"{max(a.age_ms for a in after):.0f} ms")
