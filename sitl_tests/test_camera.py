"""Camera faults: a stall (the driver delivers nothing for 3 s) and corrupt frames."""

from __future__ import annotations

import asyncio

import pytest

from companion.settings import Settings
from sitl_tests.harness import Flight, first_at_or_after, sitl_settings, wait_until
from sitl_tests.test_link import steady_fixes

#: Seconds of clean frames flown after the corrupt ones.
CLEAN_S = 3.0


async def test_camera_stall(settings: Settings) -> None:
    """The camera delivers nothing for 3 s: the status turns ``degraded`` within the stall
    timeout plus one status period (health is recomputed at the status rate when no frame
    comes: 1 s + 1 s by default), no fix
    is sent while no frame comes (none stale afterwards), then the companion is ``tracking``
    again and fixes are fused within 2 s of the camera's return."""
    stall_s = 3.0
    seen: dict[str, float] = {}

    async def script(flight: Flight) -> None:
        await steady_fixes(flight)
        assert flight.app is not None
        app = flight.app
        t0 = flight.mark("camera stall 3 s")
        flight.camera.faults.stall_until_s = t0 + stall_s
        limit = app.policy.stall_after_s + app.status_period_s + 0.2
        seen["degraded"] = await wait_until(flight, lambda: app.state == "degraded",
                                            timeout_s=limit, what="status degraded") - t0
        await wait_until(flight, lambda: app.state == "tracking", timeout_s=stall_s + 2.0,
                         what="tracking again after the stall")
        seen["tracking"] = flight.flight_s() - (t0 + stall_s)

    flight = await Flight("hover", 11.0, settings).run(script)
    t0 = flight.stimuli[0][0]
    assert flight.camera.faults.stalled_s >= stall_s - 0.2, "the camera never stalled"
    frames_in = [f for f in flight.frames if t0 + 0.2 < f.t_s < t0 + stall_s - 0.1]
    assert not frames_in, "frames were processed during the stall"
    sent = [a for a in flight.fake.arrivals if t0 + 0.3 < a.flight_s < t0 + stall_s]
    assert not sent, f"{len(sent)} fixes sent while the camera delivered nothing"
    assert not flight.stale(), flight.stale()[:3]
    back = first_at_or_after(flight.fake.accepted_times(), t0 + stall_s)
    assert back is not None and back - (t0 + stall_s) <= 2.0, back
    print(f"stall: degraded after {seen['degraded']:.2f} s, tracking {seen['tracking']:.2f} s "
          f"and fused {back - t0 - stall_s:.2f} s after the camera's return")


@pytest.fixture(scope="module")
def corrupt_frames(tmp_path_factory: pytest.TempPathFactory) -> Flight:
    """Hover; 1 s of pure-noise frames, 1 s of black frames, then 2 s of frames of the wrong
    size, then clean frames for the rest of the flight."""
    degraded: list[float] = []

    async def script(flight: Flight) -> None:
        await steady_fixes(flight)
        assert flight.app is not None
        app, cam = flight.app, flight.camera.faults
        fps = int(flight.sim.fps)
        for kind, count in (("noise", fps), ("black", fps), ("wrong_size", 2 * fps)):
            flight.mark(kind)
            cam.corrupt_kind, cam.corrupt_left = kind, count
            if kind == "wrong_size":
                degraded.append(await wait_until(flight, lambda: app.state == "degraded",
                                                 timeout_s=2.0, what="degraded by bad frames"))
            await wait_until(flight, lambda: cam.corrupt_left == 0, timeout_s=count / fps + 2,
                             what=f"{count} {kind} frames delivered")
        flight.mark("clean frames")
        await asyncio.sleep(CLEAN_S)
        app.request_stop()  # the flight ends CLEAN_S after the clean frames, however late

    settings = sitl_settings(tmp_path_factory.mktemp("corrupt_frames"))
    # long enough that the script ends it: under load the steady fixes and the corrupt
    # frames took until 12 s of a 14 s flight, leaving the clean frames 2 s (no fix came)
    flight = asyncio.run(Flight("hover", 30.0, settings).run(script))
    assert degraded, "the status never turned degraded"
    return flight


def test_no_fix_from_corrupt_frames(corrupt_frames: Flight) -> None:
    """No fix from a noise, black or wrong-size frame; wrong-size frames are counted bad and
    turn the status ``degraded`` (checked while flying)."""
    flight = corrupt_frames
    corrupted = set(flight.camera.faults.corrupted)
    assert len(corrupted) >= 4 * flight.sim.fps - 2, len(corrupted)
    processed = [f for f in flight.frames if f.index in corrupted]
    assert processed, "no corrupt frame reached the perception"
    fixed = [f.index for f in processed if f.fix_ned_m is not None]
    assert not fixed, f"fixes from corrupt frames {fixed[:5]}"
    assert flight.app is not None and flight.app.counters.bad_frames >= flight.sim.fps
    assert not flight.invented()
    print(f"corrupt frames: {len(corrupted)} delivered, {len(processed)} processed, 0 fixes; "
          f"{flight.app.counters.bad_frames} counted bad")


def test_fixes_resume_after_corrupt_frames(corrupt_frames: Flight) -> None:
    """Clean frames again: fixes are fused within 2 s."""
    clean = corrupt_frames.stimuli[-1][0]
    assert corrupt_frames.stimuli[-1][1] == "clean frames"
    assert corrupt_frames.frames[-1].t_s >= clean + CLEAN_S - 0.5, "the flight ended early"
    back = first_at_or_after(corrupt_frames.fake.accepted_times(), clean)
    assert back is not None and back - clean <= 2.0, (clean, back)
    print(f"fused again {back - clean:.2f} s after the corrupt frames")
