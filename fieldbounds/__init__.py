"""Bounds a frozen configuration dataclass declares in its field metadata, checked in one
place for every layer.

``field(metadata={"ge": 0, "lt": 1})``: ``ge``/``gt``/``le``/``lt`` bound a number and
``min_len`` a string's length. ``companion.core.validate`` checks them when it builds a
configuration from TOML; :func:`check_bounds` checks a configuration built directly in
code (``tracker.config.check_config``, ``mavlink_bridge.config.MavlinkConfig.check``).
This package sits below ``tracker``, ``mavlink_bridge`` and ``companion`` and imports
only the standard library, so that all three may use it (docs/architecture.md).
"""

from __future__ import annotations

import dataclasses
import operator
from collections.abc import Callable, Mapping
from typing import Any

#: (metadata key, symbol, test) of every numeric bound.
BOUNDS: tuple[tuple[str, str, Callable[[Any, Any], bool]], ...] = (
    ("ge", ">=", operator.ge), ("gt", ">", operator.gt),
    ("le", "<=", operator.le), ("lt", "<", operator.lt),
)


def bounds_text(meta: Mapping[str, Any]) -> list[str]:
    """The numeric bounds of a field's metadata as text, e.g. ``[">= 0", "< 1"]``."""
    return [f"{sym} {meta[key]}" for key, sym, _ in BOUNDS if key in meta]


def within_bounds(value: Any, meta: Mapping[str, Any]) -> bool:
    """Whether a number keeps every numeric bound of its field's metadata."""
    return all(test(value, meta[key]) for key, _, test in BOUNDS if key in meta)


def broken_bound(value: Any, meta: Mapping[str, Any]) -> str | None:
    """What ``value`` should have been (``"a value >= 4"``), or ``None`` when it keeps
    every bound of ``meta`` (numbers: ``ge``/``gt``/``le``/``lt``; strings: ``min_len``)."""
    if isinstance(value, str):
        need = meta.get("min_len", 0)
        return f"a string of at least {need} characters" if len(value) < need else None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    for key, sym, test in BOUNDS:
        if key in meta and not test(value, meta[key]):
            return f"a value {sym} {meta[key]}"
    return None


def check_bounds(config: Any, section: str) -> None:
    """Raise ``ValueError`` naming ``section.field`` for the first field of the dataclass
    instance ``config`` that breaks a bound in its metadata; a field holding a dataclass
    (a group of settings) is checked as ``section.field``."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            check_bounds(value, f"{section}.{f.name}")
            continue
        need = broken_bound(value, f.metadata)
        if need is not None:
            raise ValueError(f"{section}.{f.name}: expected {need}, got {value!r}")
