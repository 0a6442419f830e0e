"""Turn plain TOML data into frozen, typed config dataclasses, or say exactly what is wrong.

Every component keeps its configuration as a frozen stdlib dataclass in its own package
(``tracker``, ``mavlink_bridge`` stay free of this module).  A field declares:

* its type: ``int``, ``float``, ``bool``, ``str``, ``typing.Literal[...]``, ``tuple[T, ...]``,
  ``tuple[T1, T2]``, ``T | None`` (only as a default: TOML has no null) or another dataclass;
* every number must be finite (TOML's ``inf`` and ``nan`` are refused);
* a dataclass whose keys moved (e.g. into a nested table) may say where: a static method
  ``moved_to(key) -> str | None`` turns the old key's "unknown key" into "moved to ...";
* optional constraints in ``field(metadata=...)``: ``ge``, ``gt``, ``le``, ``lt`` (numbers),
  ``min_len`` (strings and lists), and ``path=True`` for a file path that is resolved
  relative to the config file that set it.

:func:`build` raises :class:`FieldError` carrying the dotted key path, what was expected
and what was found; :mod:`companion.settings` adds the file name and turns it into a
one-line :class:`~companion.errors.ConfigError`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from fieldbounds import bounds_text, within_bounds

T = TypeVar("T")



class FieldError(Exception):
    """A value that does not fit its field: ``key`` is the dotted path."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


def show_value(value: object) -> str:
    """A value as the user wrote it in TOML: strings quoted, booleans lower-case."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # inf, -inf, nan as TOML spells them
    try:
        return json.dumps(value, default=str)
    except (TypeError, ValueError):
        return repr(value)


_BOUNDS = ("ge", "gt", "le", "lt")


def describe(tp: Any, meta: Mapping[str, Any] | None = None) -> str:
    """A short English description of what a field accepts, constraints included."""
    meta = meta or {}
    origin = typing.get_origin(tp)
    if origin is typing.Literal:
        return "one of " + ", ".join(show_value(a) for a in typing.get_args(tp))
    if _is_optional(tp):
        return describe(_strip_optional(tp), meta)
    if origin is tuple:
        args = typing.get_args(tp)
        length = f" of at least {meta['min_len']}" if "min_len" in meta else ""
        each = " ".join(["", " and ".join(bounds_text(meta))]).rstrip()
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list{length} of {_plural(args[0])}{each}"
        return f"a list of {len(args)} {_plural(args[0])}{each}"
    base = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    if tp in base:
        text = base[tp]
        if tp is str and "pattern" in meta:
            text = f"a string matching {meta['pattern']}"
        elif tp is str and "min_len" in meta:
            text = "a non-empty string" if meta["min_len"] == 1 else text
        bounds = bounds_text(meta)
        return " ".join([text, " and ".join(bounds)]).strip()
    if dataclasses.is_dataclass(tp):
        return "a table"
    return str(tp)


def _plural(tp: Any) -> str:
    if typing.get_origin(tp) is tuple:
        return "lists"
    return {int: "integers", float: "numbers", bool: "booleans", str: "strings"}.get(
        tp, "tables" if dataclasses.is_dataclass(tp) else str(tp)
    )


def _is_optional(tp: Any) -> bool:
    return typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in (
        typing.get_args(tp)
    )


def _strip_optional(tp: Any) -> Any:
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return args[0] if len(args) == 1 else typing.Union[tuple(args)]  # noqa: UP007


PathResolver = Callable[[str, str], str]


def build(cls: type[T], data: Mapping[str, Any], prefix: str = "",
          resolve_path: PathResolver | None = None) -> T:
    """Build dataclass ``cls`` from ``data``; unknown keys and bad values raise FieldError.

    ``resolve_path(key, value)`` turns a ``path=True`` field's value into a usable path.
    """
    if not isinstance(data, Mapping):
        raise FieldError(prefix or "(top level)", f"expected a table, got {show_value(data)}")
    fields = {
        f.name: f
        for f in dataclasses.fields(cls)  # type: ignore[arg-type]
        if f.init and not f.metadata.get("internal")
    }
    hints = typing.get_type_hints(cls)
    for key in data:
        if key not in fields:
            moved = getattr(cls, "moved_to", lambda _: None)(key)
            if moved is not None:
                raise FieldError(_join(prefix, key), f"moved to {_join(prefix, moved)}")
            known = ", ".join(sorted(fields)) or "nothing"
            raise FieldError(_join(prefix, key), f"unknown key (expected one of: {known})")
    kwargs = {
        name: _convert(hints[name], data[name], _join(prefix, name), f.metadata, resolve_path)
        for name, f in fields.items()
        if name in data
    }
    return cls(**kwargs)


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _convert(tp: Any, value: Any, key: str, meta: Mapping[str, Any],
             resolve_path: PathResolver | None) -> Any:
    def fail() -> FieldError:
        return FieldError(key, f"expected {describe(tp, meta)}, got {show_value(value)}")

    origin = typing.get_origin(tp)
    if _is_optional(tp):
        return _convert(_strip_optional(tp), value, key, meta, resolve_path)
    if origin is typing.Literal:
        if value not in typing.get_args(tp) or isinstance(value, bool) != any(
            isinstance(a, bool) for a in typing.get_args(tp)
        ):
            raise fail()
        return value
    if dataclasses.is_dataclass(tp):
        return build(typing.cast(type, tp), value, key, resolve_path)
    if origin is tuple:
        return _convert_tuple(tp, value, key, meta, resolve_path, fail)
    if tp is bool:
        if not isinstance(value, bool):
            raise fail()
        return value
    if tp is int or tp is float:
        ok = isinstance(value, int) if tp is int else isinstance(value, int | float)
        if not ok or isinstance(value, bool):
            raise fail()
        number = tp(value)
        if not math.isfinite(number):  # TOML's inf and nan: no setting means either
            raise FieldError(key, f"expected a finite number, got {show_value(value)}")
        if not within_bounds(number, meta):
            raise fail()
        return number
    if tp is str:
        if not isinstance(value, str) or len(value) < meta.get("min_len", 0):
            raise fail()
        if "pattern" in meta and not re.fullmatch(meta["pattern"], value):
            raise fail()
        if meta.get("path") and resolve_path is not None and value:
            return resolve_path(key, value)
        return value
    raise FieldError(key, f"cannot configure a field of type {tp}")


def _convert_tuple(tp: Any, value: Any, key: str, meta: Mapping[str, Any],
                   resolve_path: PathResolver | None, fail: Callable[[], FieldError]) -> Any:
    if not isinstance(value, list | tuple):
        raise fail()
    args = typing.get_args(tp)
    if len(args) == 2 and args[1] is Ellipsis:
        item_types = [args[0]] * len(value)
        if len(value) < meta.get("min_len", 0):
            raise fail()
    else:
        if len(value) != len(args):
            raise fail()
        item_types = list(args)
    bounds = {k: v for k, v in meta.items() if k in _BOUNDS}  # on every item
    return tuple(
        _convert(t, v, f"{key}[{i}]", bounds, resolve_path)
        for i, (t, v) in enumerate(zip(item_types, value, strict=True))
    )


def to_plain(obj: Any) -> Any:
    """A config dataclass as plain data (tables, lists, scalars) for printing."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple | list):
        return [to_plain(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj
