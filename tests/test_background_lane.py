"""The background lane runs below the worker's scheduling priority (issue 23)."""

from __future__ import annotations

import asyncio
import os
import threading

from companion.pipeline.background import BackgroundLane


async def test_the_lane_thread_runs_at_a_lower_priority_than_the_caller() -> None:
    mine = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    seen: list[int] = []
    done = asyncio.Event()
    lane = BackgroundLane("test-lane", lambda err: None, nice=5)
    lane.submit(lambda: os.getpriority(os.PRIO_PROCESS, threading.get_native_id()),
                lambda prio: (seen.append(prio), done.set()))
    await asyncio.wait_for(done.wait(), 10.0)
    await lane.close()
    assert seen == [min(19, mine + 5)]
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == mine
