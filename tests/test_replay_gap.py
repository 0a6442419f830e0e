"""The replay's longest time without a fix (companion/replay_score.py ``GapMeter``)."""

from __future__ import annotations

import pytest

from companion.replay_score import GapMeter


def gaps(frames: list[tuple[float, bool]]) -> GapMeter:
    meter = GapMeter()
    for t_s, fixed in frames:
        meter.add(t_s, fixed)
    return meter


def test_the_longest_gap_is_between_two_fixes_and_says_where_it_began() -> None:
    m = gaps([(0.0, False), (1.0, True), (1.1, True), (1.2, False), (3.0, False), (3.1, True),
              (3.2, True)])
    assert m.longest_s == pytest.approx(2.0) and m.began_s == pytest.approx(1.1)


def test_frames_before_the_first_fix_are_not_a_gap_but_an_outage_at_the_end_is() -> None:
    m = gaps([(0.0, False), (5.0, False), (6.0, True), (6.5, True), (9.5, False)])
    assert m.longest_s == pytest.approx(3.0) and m.began_s == pytest.approx(6.5)
    none = gaps([(0.0, False), (4.0, False)])
    assert none.longest_s == 0.0 and none.began_s is None
