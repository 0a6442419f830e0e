"""One bounds check from field metadata for every layer (fieldbounds), and a configuration
built in code has its bounds checked as one read from TOML does."""

from __future__ import annotations

import pytest

from companion.core.validate import FieldError, build
from fieldbounds import broken_bound, check_bounds
from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from tracker.config import TrackerConfig, check_config, replace


def test_broken_bound_names_the_first_broken_bound() -> None:
    meta = {"ge": 0, "lt": 1}
    assert broken_bound(0.5, meta) is None
    assert broken_bound(-0.1, meta) == "a value >= 0"
    assert broken_bound(1, meta) == "a value < 1"
    assert broken_bound("", {"min_len": 1}) == "a string of at least 1 characters"
    assert broken_bound(True, {"ge": 5}) is None  # booleans are not numbers to bound


def test_a_mavlink_config_built_in_code_has_its_bounds_checked() -> None:
    """Before fieldbounds, MavlinkConfig.check() checked only its cross-field rule: a
    system id of 300 reached the link."""
    config = MavlinkConfig(endpoint="udpin:127.0.0.1:0", set_origin=False, system_id=300)
    with pytest.raises(ValueError, match=r"mavlink\.system_id: expected a value <= 255, got 300"):
        config.check()
    with pytest.raises(ValueError, match=r"mavlink\.system_id"):
        PymavlinkBridge(config)


def test_the_three_layers_agree_on_a_bound() -> None:
    """The tracker's direct check, the TOML loader and check_bounds read one rule."""
    bad = replace(TrackerConfig(), particles=2)
    need = r"filter\.particles: expected a value >= 4, got 2"
    with pytest.raises(ValueError, match=rf"^config\.{need}"):
        check_config(bad)
    with pytest.raises(ValueError, match=rf"^tracker\.{need}"):
        check_bounds(bad, "tracker")
    with pytest.raises(FieldError, match=r"tracker\.filter\.particles: .*>= 4"):
        build(TrackerConfig, {"filter": {"particles": 2}}, "tracker")
