"""benchmarks/latency_pinned.py judges each case's runs by issue 23's targets."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from benchmarks.latency_pinned import TARGETS, meets, targets


def run(p99: float, dropped: int, cores: float, frames: int = 900) -> dict[str, Any]:
    stage = {"p50": 10.0, "p99": p99, "max": p99 + 5.0}
    return {"stages": {"capture_to_worker": stage, "process": stage, "capture_to_wire": stage},
            "dropped": dropped, "frames": frames - dropped, "cores": cores, "rmse_m": 0.02}


def test_the_quiet_demo_needs_p99_drops_and_cores() -> None:
    demo = TARGETS["demo"]
    assert demo is not None
    assert meets(run(19.9, 0, 0.49), demo)
    assert not meets(run(20.1, 0, 0.49), demo)
    assert not meets(run(19.9, 1, 0.49), demo)
    assert not meets(run(19.9, 0, 0.51), demo)


def test_the_busy_demo_allows_one_percent_dropped() -> None:
    busy = TARGETS["demo-busy"]
    assert busy is not None
    assert meets(run(32.0, 9, 0.9), busy)  # 9 of 900
    assert not meets(run(32.0, 10, 0.9), busy)
    assert not meets(run(34.0, 0, 0.9), busy)


def test_the_summary_says_met_by_the_median_and_counts_the_runs() -> None:
    lines = targets({"new:demo": [run(19.0, 0, 0.45), run(21.0, 0, 0.45), run(19.5, 0, 0.45)],
                     "new:quiet": [run(40.0, 0, 0.4)], "new:busy": [run(90.0, 50, 0.5)]})
    assert "median p99 19.5 ms" in lines[0] and ": met (2 of 3 runs)" in lines[0], lines[0]
    assert "NOT met (0 of 1 runs)" in lines[1], lines[1]
    assert lines[2].endswith("(no target)"), lines[2]


def test_the_slow_cases_have_no_target_and_their_busy_loops() -> None:
    """``slow``: two busy loops on the pinned core; with ``--demo`` one pinned to each."""
    import os

    from benchmarks.latency_pinned import PINNED_HOGS, demo_hogs

    assert TARGETS["slow"] is None and TARGETS["demo-slow"] is None
    assert PINNED_HOGS == {"quiet": 0, "busy": 1, "slow": 2}
    assert demo_hogs("demo") == [] and demo_hogs("demo-busy") == [None]
    assert demo_hogs("demo-slow") == sorted(os.sched_getaffinity(0))


@pytest.mark.slow  # renders two frames twice: 0.6 s
def test_a_truth_an_older_checkout_cannot_unpickle_is_rendered_by_its_own_simulator(
        tmp_path: Path) -> None:
    """An older checkout's truth types live elsewhere: it renders the recording's truth with
    its own simulator from ``meta.json``, the same truth the recorder pickled."""
    import pickle

    from benchmarks.latency_pinned import load_truths, record

    record(tmp_path, "survey", 2 / 30)
    recorded = load_truths(tmp_path, 2)
    # a pickle naming a module this checkout does not have (as 7ad82d0 reading main's)
    unreadable = pickle.dumps(recorded)
    assert b"companion" in unreadable
    (tmp_path / "truth.pkl").write_bytes(unreadable.replace(b"companion.core", b"companion.gone"))
    with pytest.raises(ModuleNotFoundError):
        pickle.loads((tmp_path / "truth.pkl").read_bytes())
    rebuilt = load_truths(tmp_path, 2)
    assert rebuilt["scenario"] == "survey" and len(rebuilt["truths"]) == 2
    assert repr(rebuilt["truths"]) == repr(recorded["truths"])
