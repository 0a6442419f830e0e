"""BootClock: the autopilot's time_boot_ms on the companion's clock, and SensorHistory using
it for a burst of ATTITUDE read after a stall."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncGenerator

import numpy as np
import pytest

from companion.boot_clock import BootClock
from companion.sensors import SensorHistory
from mavlink_bridge.telemetry import Attitude, Telemetry
from tracker.pose.config import PoseConfig

T0_US = 5_000_000_000  # the companion's clock when the autopilot booted + 5000 s


def test_jittered_delays_map_to_the_send_time_plus_the_least_delay() -> None:
    rng = np.random.default_rng(3)
    clock = BootClock()
    errors = []
    for k in range(1, 400):  # 50 Hz for 8 s; link delay 2 ms + 0..15 ms jitter
        boot_ms = 1000 + 20 * k
        delay_us = 2000 + int(rng.uniform(0, 15_000))
        t = clock.stamp(boot_ms, T0_US + boot_ms * 1000 + delay_us)
        errors.append(t - (T0_US + boot_ms * 1000))
    late = errors[50:]  # after the first second the window holds a near-2 ms sample
    assert min(late) >= 2000 and max(late) < 2300  # the least delay, not each one's
    offset = clock.offset_us()
    assert offset is not None and 2000 <= offset - T0_US < 2300


def test_a_burst_after_a_stall_keeps_the_samples_spread() -> None:
    clock = BootClock()
    for k in range(50):  # one second at 50 Hz, each 3 ms on the wire
        clock.stamp(20 * k, T0_US + 20_000 * k + 3000)
    # a 100 ms stall: five samples sent 20 ms apart are read within 50 us
    read = T0_US + 20_000 * 54 + 3000
    stamps = [clock.stamp(20 * k, read + 10 * (k - 50)) for k in range(50, 55)]
    assert [s - stamps[0] for s in stamps] == [0, 20_000, 40_000, 60_000, 80_000]
    assert stamps[-1] == T0_US + 20_000 * 54 + 3000  # sent + the link's least delay


def test_a_reboot_starts_the_estimate_again() -> None:
    clock = BootClock()
    for k in range(1, 20):
        clock.stamp(100_000 + 20 * k, T0_US + 20_000 * k)
    # rebooted: time_boot_ms starts near 0 again, 30 s of companion time later
    arrival = T0_US + 30_000_000
    assert clock.stamp(500, arrival) == arrival
    assert clock.restarts == 1
    assert clock.stamp(520, arrival + 21_000) == arrival + 20_000


def test_an_unfilled_stamp_keeps_the_arrival() -> None:
    clock = BootClock()
    assert clock.stamp(0, T0_US) == T0_US
    assert clock.offset_us() is None


def test_the_least_delay_is_forgotten_after_the_window() -> None:
    clock = BootClock(window_us=1_000_000)
    clock.stamp(1000, T0_US + 1_000_000 + 1000)  # 1 ms on the wire, once
    for k in range(1, 100):  # then 10 ms for 2 s: the 1 ms sample leaves the window
        t = clock.stamp(1000 + 20 * k, T0_US + (1000 + 20 * k) * 1000 + 10_000)
    assert t == T0_US + (1000 + 20 * 99) * 1000 + 10_000


class _Bridge:
    """The bridge's subscribe(), fed from a list (the shape SensorHistory reads)."""

    def __init__(self, items: list[Telemetry]) -> None:
        self.items = items

    async def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        for item in self.items:
            yield item


@pytest.mark.parametrize("mapped", [True, False])
def test_sensor_history_reads_a_burst_on_the_autopilot_s_clock(mapped: bool) -> None:
    """Roll ramps at 1 rad/s; a stall delivers the last five samples at once.  Mapped, the
    attitude at a frame inside the stall is the roll of that time; by arrival it is not."""
    items = []
    for k in range(60):
        boot_ms = 20 * k
        arrival_ns = (T0_US + boot_ms * 1000 + 2000) * 1000
        if k >= 55:  # read within 50 us, 100 ms late for the first of them
            arrival_ns = (T0_US + 20 * 59 * 1000 + 2000 + 10 * (k - 55)) * 1000
        att = Attitude(boot_ms, boot_ms / 1000, 0.0, 0.0, 0.0, 0.0, 0.0)
        items.append(Telemetry("ATTITUDE", 1, 1, arrival_ns, att))
    history = SensorHistory(_Bridge(items), PoseConfig())  # type: ignore[arg-type]
    if not mapped:
        history.boot_clock = None

    async def follow() -> None:
        history.start()
        assert history._task is not None
        await history._task

    asyncio.run(follow())
    frame_us = T0_US + 1_130_000 + 2000  # the frame of boot 1.130 s (inside the stall)
    a = history.attitude_at(frame_us)
    assert a is not None
    error = abs(a.roll_rad - 1.130)
    if mapped:
        assert error < 1e-6
    else:
        assert error > 0.03  # by arrival: 1.08 s and the burst (1.10 s) 100 ms later
    assert math.isfinite(a.yaw_rad)
