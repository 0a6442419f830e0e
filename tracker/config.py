"""Configuration of the adaptive landmark tracker (TOML section ``[tracker]``).

Constraints live in field metadata (``ge``, ``gt``, ``le``, ``lt``) and are checked by the
application loader; :func:`check_config` re-checks them for direct library use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from fieldbounds import check_bounds


@dataclass(frozen=True)
class TrackerConfig:
    """Parameters of :class:`tracker.AdaptiveTracker`.

    Distances are in pixels of the *working* patch (the search region downscaled so that the
    target box covers about ``work_area_px`` pixels) unless a name says ``_frac`` (fraction of
    the box size) or ``_px_full`` (full-resolution pixels).
    """

    particles: int = field(default=20, metadata={"ge": 4, "le": 2000})
    mean_shift_fraction: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    mean_shift_iterations: int = field(default=4, metadata={"ge": 0, "le": 50})
    bins: int = field(default=16, metadata={"ge": 4, "le": 256})
    stretch_features: bool = False
    gain_compensation: Literal["colour", "always", "never"] = "colour"
    gain_source: Literal["frame", "target"] = "target"
    gain_core_frac: float = field(default=1.0, metadata={"gt": 0.0, "le": 1.0})
    gain_mode: Literal["grey", "colour"] = "grey"
    gain_deadband: float = field(default=0.0, metadata={"ge": 0.0, "lt": 1.0})
    gain_check: bool = True
    gain_rate: float = field(default=0.3, metadata={"gt": 0.0, "le": 1.0})
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
    llr_gain: float = field(default=1.5, metadata={"ge": 0.0})
    llr_vote: Literal["box", "contrast"] = "contrast"
    omega: float = field(default=50.0, metadata={"gt": 0.0})
    weight_threshold: float = field(default=0.02, metadata={"ge": 0.0, "lt": 1.0})
    motion_history_frames: int = field(default=5, metadata={"ge": 1})
    drift_gain: float = field(default=0.5, metadata={"ge": 0.0, "le": 2.0})
    motion_gain: float = field(default=1.0, metadata={"gt": 0.0})
    motion_min_frac: float = field(default=0.04, metadata={"ge": 0.0})
    motion_initial_frac: float = field(default=0.5, metadata={"ge": 0.0})
    motion_max_frac: float = field(default=0.5, metadata={"gt": 0.0})
    scale_noise: float = field(default=0.01, metadata={"ge": 0.0, "le": 0.5})
    min_scale: float = field(default=0.3, metadata={"gt": 0.0})
    max_scale: float = field(default=3.0, metadata={"gt": 1.0})
    search_margin_frac: float = field(default=0.75, metadata={"ge": 0.0})
    work_area_px: int = field(default=900, metadata={"ge": 64})
    sample_grid: int = field(default=24, metadata={"ge": 4, "le": 64})
    lost_below_confidence: float = field(default=0.15, metadata={"ge": 0.0, "le": 1.0})
    lost_after_frames: int = field(default=3, metadata={"ge": 1})
    reacquire_confidence: float = field(default=0.45, metadata={"ge": 0.0, "le": 1.0})
    reacquire_growth: float = field(default=1.5, metadata={"gt": 1.0})
    gray_tolerance: float = field(default=1.0, metadata={"ge": 0.0})
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


def check_config(config: TrackerConfig) -> None:
    """Raise ``ValueError`` naming the first field that breaks its metadata constraint."""
    check_bounds(config, "config")
    if config.top_features > 49:
        raise ValueError("config.top_features: expected <= 49")
