"""Scenarios: TOML files (config/scenarios/NAME.toml) describing a simulated flight.

The schema is :class:`ScenarioConfig` (documented in docs/sim.md).  ``load_scenario``
validates a file into it and raises :class:`~companion.errors.ConfigError` naming the
file, the key and what was expected.
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from companion.errors import ConfigError
from companion.sim.effects import EffectSpec
from companion.sim.rangefinder import RangeFinderConfig
from companion.sim.trajectory import TrajectoryConfig
from companion.sim.world import WorldConfig
from companion.sources.stream_format import Origin
from tracker.camera import CameraModel

SCENARIO_DIR = Path(__file__).resolve().parents[2] / "config" / "scenarios"


@dataclass(frozen=True)
class OriginConfig:
    """WGS84 origin of the local NED frame."""

    lat: float = field(default=47.3769, metadata={"ge": -90, "le": 90})
    lon: float = field(default=8.5417, metadata={"ge": -180, "le": 180})
    alt_m: float = 408.0

    def to_origin(self) -> Origin:
        """As the stream format's :class:`Origin`."""
        return Origin(self.lat, self.lon, self.alt_m)


@dataclass(frozen=True)
class ScenarioConfig:
    """A simulated flight: where, what is seen, how it flies, what goes wrong."""

    name: str = "unnamed"
    description: str = ""
    landmarks: str = "../landmarks.geojson"  # relative to the scenario file
    seconds: float = field(default=20.0, metadata={"gt": 0})
    fps: float = field(default=30.0, metadata={"gt": 0})
    seed: int = field(default=0, metadata={"ge": 0})
    camera_id: str = "sim0"
    origin: OriginConfig = field(default_factory=OriginConfig)
    camera: CameraModel = field(default_factory=CameraModel)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    rangefinder: RangeFinderConfig = field(default_factory=RangeFinderConfig)
    effects: tuple[EffectSpec, ...] = ()
    path: str = ""  # the file it was loaded from (set by the loader)


def _fail(where: str, expected: str, value: Any) -> ConfigError:
    return ConfigError(f"{where}: expected {expected}, got {value!r}")


def _check_limits(value: float, meta: Any, where: str) -> None:
    for key, ok, text in (
        ("ge", lambda v, b: v >= b, ">="),
        ("gt", lambda v, b: v > b, ">"),
        ("le", lambda v, b: v <= b, "<="),
        ("lt", lambda v, b: v < b, "<"),
    ):
        if key in meta and not ok(value, meta[key]):
            raise _fail(where, f"a number {text} {meta[key]}", value)


def convert(tp: Any, value: Any, where: str, meta: Any = None) -> Any:
    """Validate a TOML value against a type annotation (dataclass, tuple, Literal, scalar)."""
    meta = meta or {}
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return build(tp, value, where)
    if origin is Literal:
        if value not in typing.get_args(tp):
            raise _fail(where, "one of " + ", ".join(map(str, typing.get_args(tp))), value)
        return value
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            raise _fail(where, "a list", value)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise _fail(where, f"a list of {len(args)} values", value)
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(convert(a, v, f"{where}[{i}]") for i, (a, v) in pairs)
    if origin in (typing.Union, types.UnionType):
        return convert(next(a for a in typing.get_args(tp) if a is not type(None)), value, where)
    if tp is bool:
        if not isinstance(value, bool):
            raise _fail(where, "true or false", value)
        return value
    if tp in (int, float):
        ok = isinstance(value, int) if tp is int else isinstance(value, int | float)
        if isinstance(value, bool) or not ok:
            raise _fail(where, "an integer" if tp is int else "a number", value)
        _check_limits(value, meta, where)
        return tp(value)
    if tp is str:
        if not isinstance(value, str):
            raise _fail(where, "a string", value)
        return value
    raise ConfigError(f"{where}: unsupported type {tp}")


def build(cls: Any, data: Any, where: str) -> Any:
    """A frozen dataclass from a TOML table; unknown keys are errors (typos must not pass)."""
    if not isinstance(data, dict):
        raise _fail(where, "a table", data)
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}: unknown key (known: {', '.join(known)})")
    kwargs = {
        name: convert(hints[name], value, f"{where}.{name}", known[name].metadata)
        for name, value in data.items()
    }
    return cls(**kwargs)


def scenario_path(name_or_file: str) -> Path:
    """A scenario name (config/scenarios/NAME.toml) or a file path."""
    path = Path(name_or_file)
    if path.suffix == ".toml" or path.exists():
        return path
    return SCENARIO_DIR / f"{name_or_file}.toml"


def load_scenario(name_or_file: str) -> ScenarioConfig:
    """Read and validate a scenario; errors name the file and the key."""
    path = scenario_path(name_or_file)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        known = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.toml")))
        raise ConfigError(f"{path}: no such scenario (built-in: {known})") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML ({err})") from err
    data.setdefault("name", path.stem)
    config: ScenarioConfig = build(ScenarioConfig, data, str(path))
    return dataclasses.replace(config, path=str(path))


def landmarks_path(config: ScenarioConfig) -> Path:
    """The landmark map of a scenario (relative paths are relative to the scenario file)."""
    p = Path(config.landmarks)
    if p.is_absolute() or not config.path:
        return p
    return Path(config.path).parent / p
