"""The replay benchmark's seed lists and its per-target tally (benchmarks/replay_worlds.py)."""

from __future__ import annotations

import pytest

from benchmarks.replay_worlds import HELD_OUT_SEEDS, parse_seeds, tally


def test_ranges_and_lists_mix_in_order_once_each() -> None:
    assert parse_seeds("0-3") == [0, 1, 2, 3]
    assert parse_seeds("2,5") == [2, 5]
    assert parse_seeds("0-2,8, 1,10-11") == [0, 1, 2, 8, 10, 11]
    assert parse_seeds("7") == [7]


def test_the_held_out_worlds_are_sixteen_apart_from_the_tuned_ones() -> None:
    held = parse_seeds(HELD_OUT_SEEDS)
    assert len(held) == 16
    assert not set(held) & set(parse_seeds("0-11"))
    assert not set(held) & {20, 21, 22, 23, 24, 25, 26, 27, 30, 31, 32, 33}  # the variants'


@pytest.mark.parametrize("text", ["a", "3-", "-3", "1-x", "2;5"])
def test_a_bad_seed_list_is_refused_with_the_part_named(text: str) -> None:
    with pytest.raises(ValueError, match="not a seed"):
        parse_seeds(text)


def test_the_tally_counts_each_target_over_the_worlds() -> None:
    good = {"share": 0.95, "rmse_pct": 0.3, "nees_inside": 0.93, "wrong_frames": 2,
            "light_step_s": 0.5}
    worse = good | {"nees_inside": 0.85, "rmse_pct": 0.6}
    assert tally([good, worse, good]) == \
        "share 3 of 3, RMSE 2 of 3, NEES 2 of 3, wrong 3 of 3, step 3 of 3"
    assert tally([]) == "share 0 of 0, RMSE 0 of 0, NEES 0 of 0, wrong 0 of 0, step 0 of 0"
