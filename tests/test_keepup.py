"""Frames dropped because the processing is slower than the camera make one warning (a log
line, an event, a STATUSTEXT, the status's warnings) and its end another (issue 23)."""

from __future__ import annotations

import asyncio
import io
import logging
from typing import Any

import pytest

from companion.app import CompanionApp
from companion.demo import print_summary
from companion.pipeline.keepup import KeepUpPolicy, KeepUpWatch
from tests.test_app import ListSource, Processor, Recorder, Sink


def feed(watch: KeepUpWatch, seconds: range, dropped_per_s: int, start: tuple[int, int]
         ) -> tuple[list[bool | None], tuple[int, int]]:
    """30 frames a second come, ``dropped_per_s`` of them dropped; returns the changes."""
    frames, dropped = start
    changes = []
    for t in seconds:
        frames += 30 - dropped_per_s
        dropped += dropped_per_s
        changes.append(watch.update(float(t), frames, dropped))
    return changes, (frames, dropped)


def test_a_steady_share_over_the_threshold_warns_once_and_its_end_once() -> None:
    watch = KeepUpWatch()  # 10 s window, behind over 5 %, caught up at 1 % or less
    changes, counts = feed(watch, range(0, 30), 3, (0, 0))  # 10 % dropped
    assert changes.count(True) == 1 and False not in changes
    assert changes.index(True) == 2  # once 60 frames came after the first count
    assert watch.warning() == "falling behind the camera: 30 of 300 frames dropped in the " \
                              "last 10 s (10 %)"
    changes, counts = feed(watch, range(30, 45), 1, counts)  # 3.3 %: still behind
    assert changes == [None] * 15 and watch.behind
    changes, _ = feed(watch, range(45, 70), 0, counts)
    assert changes.count(False) == 1 and True not in changes
    # the last 10 s's drops fall to 3 of 300 (1 %) at 51 s, the last drop at 44 s
    assert changes.index(False) == 51 - 45, changes
    assert watch.warning() is None


def test_a_burst_shorter_than_the_share_or_too_few_frames_says_nothing() -> None:
    watch = KeepUpWatch()
    assert watch.update(0.0, 0, 0) is None
    assert watch.update(1.0, 20, 30) is None  # 50 frames: under min_frames
    watch = KeepUpWatch()
    changes, counts = feed(watch, range(0, 20), 0, (0, 0))
    changes += [watch.update(20.0, counts[0] + 15, counts[1] + 15)]  # 15 in one second
    assert changes == [None] * 21 and not watch.behind  # 15 of 300: exactly 5 %


async def test_the_app_warns_when_its_worker_falls_behind(caplog: pytest.LogCaptureFixture
                                                          ) -> None:
    sink, rec = Sink(), Recorder()
    # 100 frames a second for a worker that needs 30 ms a frame: two in three dropped
    app = CompanionApp(ListSource(150, period_s=0.01), Processor(delay_s=0.03), sink, rec,
                       "v1", status_period_s=0.1)
    app.keep_up = KeepUpWatch(KeepUpPolicy(window_s=0.5, min_frames=20))
    with caplog.at_level(logging.WARNING, logger="companion.app"):
        await asyncio.wait_for(app.run(), timeout=30)
    events = [e for e in rec.topic("events") if e["event"] == "falling-behind"]
    assert len(events) == 1 and events[0]["share"] > 0.3, events
    assert any(t.endswith("% of camera frames dropped (CPU)") for t in sink.texts), sink.texts
    assert any("falling behind the camera" in r.message and "docs/deploy.md" in r.message
               for r in caplog.records), [r.message for r in caplog.records]
    warned = [s for s in rec.topic("status")
              if any(w.startswith("falling behind the camera") for w in s["warnings"])]
    assert warned, "no status carried the warning"


def summary(frames: int, dropped: int, behind: int | None = None) -> dict[str, Any]:
    return {"frames": frames, "flown_s": 30.0, "fps": 30.0, "dropped_frames": dropped,
            "frames_behind": dropped if behind is None else behind,
            "fixes_sent": 800, "fixes_accepted": 800, "fixes_accepted_ratio": 1.0,
            "position_rmse_m": 0.02, "mean_landmark_distance_m": 11.0,
            "position_rmse_pct_of_distance": 0.18, "nees_inside_95": 0.8,
            "attitude_prior_rejected": 0, "nees_by_landmarks": {}, "latency_p50_ms": 12.0,
            "latency_p99_ms": 19.0, "cpu_cores_busy": 0.45, "cpu_cores_busy_total": 0.9}


def test_the_demo_summary_says_when_the_machine_did_not_keep_up() -> None:
    out = io.StringIO()
    print_summary(summary(890, 10), out)  # 10 of 900: over 1 %
    assert "10 of 900 frames dropped: this machine did not keep up" in out.getvalue()
    out = io.StringIO()
    print_summary(summary(891, 9), out)
    assert "did not keep up" not in out.getvalue()
    out = io.StringIO()  # a recording's 10 unreadable frames are not the machine's fault
    print_summary(summary(890, 10, behind=0), out)
    assert "did not keep up" not in out.getvalue()
