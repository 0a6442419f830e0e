"""The harness's own checks: a wait fails when its condition never holds long enough."""

from __future__ import annotations

import time
from typing import Any

import pytest

from sitl_tests.harness import first_at_or_after, max_gap_s, wait_until


class Clock:
    """Stands in for a Flight: only ``flight_s`` is used by ``wait_until``."""

    def __init__(self) -> None:
        self.t0 = time.monotonic()

    def flight_s(self) -> float:
        return time.monotonic() - self.t0


async def test_wait_fails_naming_the_stimulus_that_never_happened() -> None:
    clock: Any = Clock()
    with pytest.raises(AssertionError, match=r"the reboot: not within 0\.2 s"):
        await wait_until(clock, lambda: False, timeout_s=0.2, what="the reboot")


async def test_wait_needs_the_condition_held() -> None:
    clock: Any = Clock()
    flicker = iter([True, False] * 1000)
    with pytest.raises(AssertionError, match="not held"):
        await wait_until(clock, lambda: next(flicker), timeout_s=0.2, hold_s=0.1, what="x")
    since = await wait_until(clock, lambda: clock.flight_s() > 0.1, timeout_s=1.0,
                             hold_s=0.1, what="y")
    assert since >= 0.1 and clock.flight_s() >= since + 0.1


def test_gap_and_first_after() -> None:
    assert max_gap_s([1.0, 1.5, 3.5], 0.0, 4.0) == 2.0
    assert max_gap_s([], 2.0, 5.0) == 3.0
    assert first_at_or_after([1.0, 2.0, 3.0], 1.5) == 2.0
    assert first_at_or_after([1.0], 1.5) is None
