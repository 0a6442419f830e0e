"""``companion replay --fast`` on the recording's clock: the frames are stamped with the
recording's times and the autopilot's messages arrive before their frame, however long the
processing takes, so that a replay gives the same fixes on a quiet or a loaded machine
(issue 25: before, frames were stamped at their delivery, and a loaded machine's replay of
a real-imagery world gave 0.749 of its fixes inside the NEES bound where a quiet one gave
0.802)."""

from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import Any

import pytest

from companion.perception import Perception
from tests.run_helpers import synth
from tests.test_replay import replay

#: the perception's own step, wrapped afresh by each replay below
PROCESS = Perception.process


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """5 s of the survey world (one-plate and two-plate fixes)."""
    return synth(tmp_path_factory.mktemp("clock") / "survey", seconds=5.0)


def _replay_recording(tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch,
                      stall_s: float) -> tuple[dict[str, Any], list[tuple[int, int]],
                                               list[tuple[float, ...]]]:
    """Replay ``stream`` --fast with every fifth frame's processing held ``stall_s``
    longer (a loaded machine); -> the summary, each frame's (index, stamp) as the
    perception saw it, and each fix's position."""
    seen: list[tuple[int, int]] = []
    fixes: list[tuple[float, ...]] = []

    def slow(self: Perception, frame: Any) -> Any:
        seen.append((frame.index, frame.t_us))
        if stall_s and frame.index % 5 == 0:
            time.sleep(stall_s)
        result = PROCESS(self, frame)
        if result.fix is not None:
            fixes.append(tuple(result.fix.position_ned_m))
        return result

    monkeypatch.setattr(Perception, "process", slow)
    status, s = replay(tmp_path, stream)
    assert status == 0
    return s, seen, fixes


def test_fast_replay_is_on_the_recordings_clock_whatever_the_load(
        tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    quiet, seen, fixes = _replay_recording(tmp_path / "quiet", stream, monkeypatch, 0.0)
    loaded, seen_l, fixes_l = _replay_recording(tmp_path / "loaded", stream, monkeypatch,
                                                0.08)
    assert len(seen) == len(seen_l) == 150 and fixes, (len(seen), len(seen_l), len(fixes))
    # stamped with the recording's times: 30 fps, 33333-33334 us apart, stalls or not
    for frames in (seen, seen_l):
        steps = {b[1] - a[1] for a, b in itertools.pairwise(frames)}
        assert steps <= {33_333, 33_334}, steps
    # the same fixes, to the last bit, and the same scores
    assert fixes_l == fixes
    for key in ("fixes_solved", "position_rmse_m", "nees_inside_95", "attitude_error_deg"):
        assert loaded[key] == quiet[key], key
    # every fix reached the fake, and its age is its processing's (the stalled ones too)
    assert loaded["fixes_sent"] == loaded["fixes_solved"], loaded["fixes_refused"]
    assert quiet["latency_p50_ms"] < loaded["latency_p99_ms"]
