"""Configuration of the adaptive landmark tracker (TOML section ``[tracker]``).

The fields are grouped by concern, one frozen dataclass (and one TOML table) per group:

========================  ==================================================================
``[tracker.filter]``       the particle filter: particles, the mean-shifted share, the
                           Bhattacharyya weight, the weight threshold, the likelihood vote,
                           the kernel's sample grid, the search window
``[tracker.motion]``       the motion model: adaptive noise (eq. 1), drift, scale
``[tracker.features]``     the appearance model: feature bins, joint histograms, the
                           variance-ratio ranking (eq. 6-8) and its re-ranking, model update
``[tracker.illumination]`` the illumination gain (``tracker/illumination.py``)
``[tracker.lost]``         when the target counts as lost and how it is searched for again
``[tracker.refine]``       the template and size filters (``tracker/refine.py``)
========================  ==================================================================

A field keeps its name inside its group (``tracker.filter.particles``); every name is unique
across the groups, so :func:`replace` takes the bare names.  Constraints live in field
metadata (``ge``, ``gt``, ``le``, ``lt``) and are checked by the application loader;
:func:`check_config` re-checks them for direct library use.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

from fieldbounds import check_bounds


@dataclass(frozen=True)
class FilterConfig:
    """The particle filter (paper sec. 3-4).

    Distances are in pixels of the *working* patch (the search region downscaled so that the
    target box covers about ``work_area_px`` pixels) unless a name says ``_frac`` (fraction of
    the box size).
    """

    particles: int = field(default=20, metadata={"ge": 4, "le": 2000})
    mean_shift_fraction: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    mean_shift_iterations: int = field(default=4, metadata={"ge": 0, "le": 50})
    omega: float = field(default=50.0, metadata={"gt": 0.0})
    weight_threshold: float = field(default=0.02, metadata={"ge": 0.0, "lt": 1.0})
    llr_gain: float = field(default=1.5, metadata={"ge": 0.0})
    llr_vote: Literal["box", "contrast"] = "contrast"
    sample_grid: int = field(default=24, metadata={"ge": 4, "le": 64})
    search_margin_frac: float = field(default=0.75, metadata={"ge": 0.0})
    work_area_px: int = field(default=900, metadata={"ge": 64})


@dataclass(frozen=True)
class MotionConfig:
    """The motion model: eq. 1's adaptive noise (fractions of the box side), drift, scale."""

    motion_history_frames: int = field(default=5, metadata={"ge": 1})
    drift_gain: float = field(default=0.5, metadata={"ge": 0.0, "le": 2.0})
    motion_gain: float = field(default=1.0, metadata={"gt": 0.0})
    motion_min_frac: float = field(default=0.04, metadata={"ge": 0.0})
    motion_initial_frac: float = field(default=0.5, metadata={"ge": 0.0})
    motion_max_frac: float = field(default=0.5, metadata={"gt": 0.0})
    scale_noise: float = field(default=0.01, metadata={"ge": 0.0, "le": 0.5})
    min_scale: float = field(default=0.3, metadata={"gt": 0.0})
    max_scale: float = field(default=3.0, metadata={"gt": 1.0})


@dataclass(frozen=True)
class FeaturesConfig:
    """The appearance model: features, histograms, ranking (eq. 6-8), model update."""

    bins: int = field(default=16, metadata={"ge": 4, "le": 256})
    stretch_features: bool = False
    appearance: Literal["joint", "marginal"] = "joint"
    joint_bins: int = field(default=8, metadata={"ge": 2, "le": 32})
    top_features: int = field(default=3, metadata={"ge": 1, "le": 49})
    max_feature_cosine: float = field(default=0.6, metadata={"ge": 0.0, "le": 1.0})
    rerank_every_frames: int = field(default=10, metadata={"ge": 1})
    rerank_below_confidence: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    anchor_weight: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    model_update_rate: float = field(default=0.05, metadata={"ge": 0.0, "le": 1.0})
    ring_area_ratio: float = field(default=1.0, metadata={"gt": 0.0, "le": 8.0})
    loglik_floor: float = field(default=0.001, metadata={"gt": 0.0, "lt": 1.0})
    gray_tolerance: float = field(default=1.0, metadata={"ge": 0.0})


@dataclass(frozen=True)
class IlluminationConfig:
    """The illumination gain (``tracker/illumination.py``)."""

    gain_compensation: Literal["colour", "always", "never"] = "colour"
    gain_source: Literal["frame", "target"] = "target"
    gain_core_frac: float = field(default=1.0, metadata={"gt": 0.0, "le": 1.0})
    gain_mode: Literal["grey", "colour"] = "grey"
    gain_deadband: float = field(default=0.0, metadata={"ge": 0.0, "lt": 1.0})
    gain_check: bool = True
    gain_rate: float = field(default=0.3, metadata={"gt": 0.0, "le": 1.0})


@dataclass(frozen=True)
class LostConfig:
    """When the target counts as lost, and the widening search that finds it again."""

    lost_below_confidence: float = field(default=0.15, metadata={"ge": 0.0, "le": 1.0})
    lost_after_frames: int = field(default=3, metadata={"ge": 1})
    reacquire_confidence: float = field(default=0.45, metadata={"ge": 0.0, "le": 1.0})
    reacquire_growth: float = field(default=1.5, metadata={"gt": 1.0})


@dataclass(frozen=True)
class RefineConfig:
    """The template and the size filters (``tracker/refine.py``)."""

    template_refine: bool = True
    template_search_frac: float = field(default=0.3, metadata={"gt": 0.0, "le": 2.0})
    template_accept_score: float = field(default=0.5, metadata={"ge": -1.0, "le": 1.0})
    template_update_score: float = field(default=0.5, metadata={"ge": -1.0, "le": 1.0})
    scale_update_score: float = field(default=0.7, metadata={"ge": -1.0, "le": 1.0})
    scale_read_score: float = field(default=0.5, metadata={"ge": -1.0, "le": 1.0})
    template_rival_margin: float = field(default=0.1, metadata={"ge": 0.0, "le": 2.0})
    template_jump_frac: float = field(default=0.25, metadata={"gt": 0.0})
    template_update_rate: float = field(default=0.1, metadata={"ge": 0.0, "le": 1.0})
    template_anchor: float = field(default=0.3, metadata={"ge": 0.0, "le": 1.0})
    size_filters: Literal["scale", "scale+aspect", "width+height"] = "width+height"
    scale_filter_scales: int = field(default=17, metadata={"ge": 3, "le": 65})
    scale_filter_step: float = field(default=1.02, metadata={"gt": 1.0, "le": 1.2})
    scale_filter_rate: float = field(default=0.025, metadata={"ge": 0.0, "le": 1.0})


@dataclass(frozen=True)
class TrackerConfig:
    """Parameters of :class:`tracker.AdaptiveTracker`, one group per concern."""

    filter: FilterConfig = field(default_factory=FilterConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    illumination: IlluminationConfig = field(default_factory=IlluminationConfig)
    lost: LostConfig = field(default_factory=LostConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)

    @staticmethod
    def moved_to(key: str) -> str | None:
        """Where a key of the flat ``[tracker]`` table (before the groups) is now:
        ``"particles"`` -> ``"filter.particles"`` (the loader says so instead of "unknown")."""
        group = GROUP_OF.get(key)
        return f"{group}.{key}" if group is not None else None


#: The group of every field, by its bare name (``"particles"`` -> ``"filter"``).
GROUP_OF: dict[str, str] = {
    f.name: group.name
    for group in dataclasses.fields(TrackerConfig)
    for f in dataclasses.fields(getattr(TrackerConfig(), group.name))
}


def replace(config: TrackerConfig, **changes: Any) -> TrackerConfig:
    """``config`` with fields replaced by their bare names, each in its group
    (``replace(c, particles=40)`` sets ``c.filter.particles``)."""
    by_group: dict[str, dict[str, Any]] = {}
    for name, value in changes.items():
        if name not in GROUP_OF:
            raise KeyError(f"TrackerConfig has no field {name!r}")
        by_group.setdefault(GROUP_OF[name], {})[name] = value
    groups = {
        group: dataclasses.replace(getattr(config, group), **values)
        for group, values in by_group.items()
    }
    return dataclasses.replace(config, **groups)


def check_config(config: TrackerConfig) -> None:
    """Raise ``ValueError`` naming the first field that breaks its metadata constraint
    (``config.filter.particles: expected a value >= 4, got 2``)."""
    check_bounds(config, "config")
