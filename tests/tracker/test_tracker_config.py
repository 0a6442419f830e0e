"""The tracker's configuration groups: every field in one group, set by its bare name."""

from __future__ import annotations

import dataclasses

import pytest

from tracker.config import GROUP_OF, TrackerConfig, replace

CFG = TrackerConfig()


def test_replace_puts_each_bare_name_in_its_group() -> None:
    config = replace(CFG, particles=40, gain_rate=0.5, template_refine=False)
    assert config.filter.particles == 40
    assert config.illumination.gain_rate == 0.5
    assert config.refine.template_refine is False
    assert config.motion == CFG.motion
    with pytest.raises(KeyError, match="no field 'partciles'"):
        replace(CFG, partciles=40)


def test_every_field_is_in_exactly_one_group() -> None:
    groups = [getattr(CFG, g.name) for g in dataclasses.fields(CFG)]
    names = [f.name for g in groups for f in dataclasses.fields(g)]
    assert len(names) == len(set(names)) == len(GROUP_OF) == 57
    assert TrackerConfig.moved_to("omega") == "filter.omega"
    assert TrackerConfig.moved_to("filter") is None
