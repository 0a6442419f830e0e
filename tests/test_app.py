"""The pipeline's orchestration with test doubles: newest frame wins, health, shutdown."""

from __future__ import annotations

import asyncio
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from companion.app import CompanionApp, FrameResult, ResultObserver, now_us
from companion.perception_types import TrackView
from companion.pipeline.health import Blocker, HealthInputs, health_state
from companion.pipeline.latest import LatestSlot, SlotClosedError
from companion.pipeline.stats import RateMeter, Rolling
from tracker.pose.types import PoseFix


@dataclass(frozen=True)
class FakeFrame:
    index: int
    t_us: int
    image: Any


class ListSource:
    def __init__(self, n: int, period_s: float = 0.0) -> None:
        self.n = n
        self.i = 0
        self.period_s = period_s

    async def recv(self) -> FakeFrame:
        if self.i >= self.n:
            raise EOFError
        await asyncio.sleep(self.period_s)
        self.i += 1
        return FakeFrame(self.i, now_us(), np.zeros((2, 2, 3), np.uint8))


class Processor:
    def __init__(self, delay_s: float = 0.0, track_from: int = 0) -> None:
        self.delay_s = delay_s
        self.track_from = track_from
        self.seen: list[int] = []
        self.thread_names: set[str] = set()
        self.housekept: list[int] = []

    def housekeeping(self, frame: Any) -> None:
        self.housekept.append(frame.index)

    def process(self, frame: Any) -> FrameResult:
        time.sleep(self.delay_s)
        self.seen.append(frame.index)
        self.thread_names.add(threading.current_thread().name)
        tracking = frame.index >= self.track_from
        return FrameResult(
            frame.index, frame.t_us,
            tracks=(TrackView("a", (1.0, 2.0, 3.0, 4.0), 0.9, (), None),) if tracking else (),
            fix=PoseFix(frame.t_us, (0.0, 0.0, float(frame.index)), (0.0, 0.0, 0.0),
                        np.eye(6), 90, ("a",), "pnp") if tracking else None,
        )


class Sink:
    def __init__(self, link_up: bool = True) -> None:
        self.link_up = link_up
        self.fixes: list[Any] = []
        self.health: list[str] = []
        self.texts: list[str] = []

    def set_health(self, state: str) -> None:
        if not self.health or self.health[-1] != state:
            self.health.append(state)

    async def send_fix(self, fix: Any) -> bool:
        self.fixes.append(fix)
        return True

    async def statustext(self, text: str) -> None:
        self.texts.append(text)

    def autopilot_position_ned(self) -> list[float] | None:
        return [1.0, 2.0, -3.0]


class Recorder:
    def __init__(self) -> None:
        self.items: list[tuple[str, dict[str, Any]]] = []

    def report(self, topic: str, t_us: int, data: dict[str, Any]) -> None:
        self.items.append((topic, data))

    def preview_due(self) -> bool:
        return True

    def preview(self, jpeg: bytes) -> None:
        self.items.append(("preview", {"bytes": len(jpeg)}))

    def topic(self, name: str) -> list[dict[str, Any]]:
        return [d for t, d in self.items if t == name]


#: Events a processed frame may cause (companion/app.py): after the source ended, the frames
#: in hand are still processed.
FRAME_EVENTS = {"health", "no-fix", "no-fix-cleared"}


class Observer(ResultObserver):
    """Notes every call with its thread and what the processor had done by then."""

    def __init__(self, name: str, calls: list[tuple[str, str, int]], proc: Processor) -> None:
        self.name, self.calls, self.proc = name, calls, proc
        self.threads: dict[str, set[str]] = {"result": set(), "after": set()}

    def on_result(self, frame: Any, result: FrameResult) -> None:
        assert result.frame_index == frame.index and self.proc.seen[-1] == frame.index
        self.threads["result"].add(threading.current_thread().name)
        self.calls.append((self.name, "result", frame.index))

    def on_after_work(self, frame: Any) -> None:
        assert self.proc.housekept[-1] == frame.index  # after the frame's housekeeping
        self.threads["after"].add(threading.current_thread().name)
        self.calls.append((self.name, "after", frame.index))

    def pose_fields(self, result: FrameResult) -> dict[str, Any]:
        return {f"{self.name}_frame": result.frame_index}


async def test_observers_see_each_result_and_after_work_in_order() -> None:
    """The observer contract (docs/architecture.md): on_result in the worker thread after
    process, in the order given; on_after_work on the lane after housekeeping; pose_fields
    go into the pose report (after the fix's own fields, before the autopilot's position),
    the frozen result is left as it is."""
    proc, sink, rec = Processor(track_from=3), Sink(), Recorder()
    calls: list[tuple[str, str, int]] = []
    first, second = Observer("a", calls, proc), Observer("b", calls, proc)
    app = CompanionApp(ListSource(6, period_s=0.01), proc, sink, rec, "v1",
                       status_period_s=0.05, observers=(first, second))
    await asyncio.wait_for(app.run(), timeout=10)
    results = [(n, i) for n, what, i in calls if what == "result"]
    assert results == [(n, i) for i in range(1, 7) for n in ("a", "b")]
    after = [(n, i) for n, what, i in calls if what == "after"]
    assert after == [(n, i) for i in proc.housekept for n in ("a", "b")]
    assert first.threads == {"result": {"companion-worker_0"},
                             "after": {"companion-background_0"}}
    poses = rec.topic("pose")
    own = ["position_ned_m", "attitude_rpy_rad", "covariance_diag", "quality",
           "landmark_ids", "solver", "attitude_prior"]  # companion.reporting.pose_json
    assert [list(p) for p in poses] == [[*own, "a_frame", "b_frame",
                                         "autopilot_position_ned_m"]] * 4
    assert [p["b_frame"] for p in poses] == [3, 4, 5, 6]


async def test_every_frame_processed_when_the_worker_keeps_up() -> None:
    proc, sink, rec = Processor(track_from=3), Sink(), Recorder()
    app = CompanionApp(ListSource(10, period_s=0.005), proc, sink, rec, "v1",
                       status_period_s=0.05)
    await asyncio.wait_for(app.run(), timeout=10)
    assert proc.seen == list(range(1, 11))
    assert proc.housekept == proc.seen  # after every frame, once its fix is out
    assert app.counters.frames == 10
    assert app.counters.fixes_sent == 8
    assert [int(f.position_ned_m[2]) for f in sink.fixes] == list(range(3, 11))
    assert proc.thread_names == {"companion-worker_0"}  # heavy work off the event loop
    assert app.stats.capture_to_wire_ms.count == 8
    assert "tracking" in sink.health
    assert sink.texts == ["stopped after 10 frames"]
    events = [e["event"] for e in rec.topic("events")]
    # The source's end is reported once; the frames in hand are finished after it (their
    # health and no-fix events may come in between); "stopped" is the last event; nothing
    # failed.
    assert events[-1] == "stopped" and events.count("source-ended") == 1
    assert set(events[events.index("source-ended") + 1:-1]) <= FRAME_EVENTS
    assert not {"source-failed", "worker-failed"} & set(events)
    assert rec.topic("status")[-1]["counters"]["frames"] == 10
    assert rec.topic("pose")[-1]["autopilot_position_ned_m"] == [1.0, 2.0, -3.0]


async def test_a_slow_worker_sees_the_newest_frames_and_drops_are_counted() -> None:
    proc = Processor(delay_s=0.03)
    app = CompanionApp(ListSource(40, period_s=0.002), proc, Sink(), Recorder(), "v1")
    await asyncio.wait_for(app.run(), timeout=20)
    assert app.dropped_frames > 0
    assert len(proc.seen) + app.dropped_frames == 40
    assert proc.seen == sorted(proc.seen)
    assert proc.seen[-1] == 40  # the last frame is never dropped at shutdown


async def test_stop_request_finishes_the_current_frame_and_exits() -> None:
    proc = Processor(delay_s=0.05)
    app = CompanionApp(ListSource(10_000, period_s=0.01), proc, Sink(), Recorder(), "v1")
    task = asyncio.create_task(app.run())
    await asyncio.sleep(0.3)
    app.request_stop()
    await asyncio.wait_for(task, timeout=5)
    assert app.counters.frames == len(proc.seen)  # nothing processed is left unhandled
    assert 0 < app.counters.frames < 100


async def test_link_down_is_the_health_state() -> None:
    sink = Sink(link_up=False)
    app = CompanionApp(ListSource(5), Processor(), sink, Recorder(), "v1")
    await asyncio.wait_for(app.run(), timeout=10)
    assert sink.health[:2] == ["starting", "link-down"]
    assert "tracking" not in sink.health


async def test_seconds_limit_stops_an_endless_source() -> None:
    app = CompanionApp(ListSource(10**9, period_s=0.01), Processor(), Sink(), Recorder(), "v")
    start = time.monotonic()
    await asyncio.wait_for(app.run(seconds=0.3), timeout=5)
    assert time.monotonic() - start < 3.0
    assert app.counters.frames > 0


def inputs(**kw: Any) -> HealthInputs:
    base: dict[str, Any] = {"now_s": 10.0, "frames_processed": 5, "last_frame_s": 9.9,
                            "last_fix_s": 9.9, "ever_tracked": True, "link_up": True}
    return HealthInputs(**{**base, **kw})


@pytest.mark.parametrize(("kw", "state"), [
    ({"frames_processed": 0, "last_frame_s": None}, "starting"),
    ({}, "tracking"),
    ({"link_up": False}, "link-down"),
    ({"last_frame_s": 8.0}, "degraded"),
    ({"bad_frame_ratio": 0.6}, "degraded"),
    ({"last_fix_s": 8.0}, "lost"),
    ({"last_fix_s": None, "ever_tracked": False}, "searching"),
    ({"last_fix_s": 9.3}, "tracking"),  # 0.7 s ago: not fresh, not yet lost
    # a known reason no fix can come wins over everything but a fresh fix (issue 24)
    ({"last_fix_s": None, "ever_tracked": False, "blocker": Blocker("no-references", "")},
     "blocked"),
    ({"frames_processed": 0, "last_frame_s": None, "last_fix_s": None,
      "blocker": Blocker("origin-far", "")}, "blocked"),
    ({"blocker": Blocker("none-in-view", "")}, "tracking"),  # a fix came: not blocked
])
def test_health_states(kw: dict[str, Any], state: str) -> None:
    assert health_state(inputs(**kw)) == state


async def test_latest_slot_keeps_newest_and_closes() -> None:
    slot: LatestSlot[int] = LatestSlot()
    slot.put(1)
    slot.put(2)
    assert await slot.get() == 2
    assert slot.dropped == 1
    slot.put(3)
    slot.close()
    assert await slot.get() == 3  # closing does not lose what is there
    with pytest.raises(SlotClosedError):
        await slot.get()


def test_rolling_percentiles_and_rate() -> None:
    r = Rolling(size=100)
    assert r.percentile(50) is None
    for v in range(1, 101):
        r.add(v)
    assert r.summary() == {"min": 1.0, "p50": 50.5, "p99": 99.01}
    m = RateMeter(window_s=1.0)
    for i in range(11):
        m.tick(i * 0.1)
    assert m.rate(1.0) == pytest.approx(10.0)


class Broken(Processor):
    def process(self, frame: Any) -> FrameResult:
        if frame.index == 3:
            raise RuntimeError("boom")
        return super().process(frame)


async def test_a_failing_processor_stops_the_flight_with_a_reason() -> None:
    rec = Recorder()
    app = CompanionApp(ListSource(10_000, period_s=0.01), Broken(), Sink(), rec, "v1")
    await asyncio.wait_for(app.run(), timeout=10)  # ends by itself, does not hang
    assert app.counters.worker_errors == 1
    failed = [e for e in rec.topic("events") if e["event"] == "worker-failed"]
    assert failed and failed[0]["reason"] == "RuntimeError: boom"


async def test_the_run_freezes_start_up_for_the_gc_and_thaws_at_the_end() -> None:
    """Issue 23: frames are processed with start-up's objects out of the collector's walks;
    undone when the run returns."""
    import gc

    seen: list[int] = []

    class Probe(Processor):
        def process(self, frame: Any) -> FrameResult:
            seen.append(gc.get_freeze_count())
            return super().process(frame)

    start_up = [object() for _ in range(100)]  # what start-up made and keeps
    app = CompanionApp(ListSource(3, period_s=0.01), Probe(), Sink(), Recorder(), "v1")
    await asyncio.wait_for(app.run(), timeout=10)
    assert len(seen) == 3
    assert all(frozen >= len(start_up) for frozen in seen)
    assert gc.get_freeze_count() == 0
