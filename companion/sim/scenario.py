"""Scenarios: TOML files (config/scenarios/NAME.toml) describing a simulated flight.

The schema is :class:`ScenarioConfig` (documented in docs/sim.md).  ``load_scenario``
validates a file into it and raises :class:`~companion.errors.ConfigError` naming the
file, the key and what was expected.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from companion.core.resources import scenario_dir, scenario_path
from companion.core.stream_format import Origin
from companion.core.validate import FieldError, build
from companion.errors import ConfigError
from companion.sim.effects import EffectSpec
from companion.sim.rangefinder import RangeFinderConfig
from companion.sim.trajectory import TrajectoryConfig
from companion.sim.world import WorldConfig
from tracker.camera import CameraModel

#: The built-in scenarios: shipped configuration, found through importlib.resources.
SCENARIO_DIR = scenario_dir()


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
    landmarks: str = field(default="../landmarks.geojson", metadata={"path": True})
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
    path: str = field(default="", metadata={"internal": True})  # set by the loader


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

    def resolve(_key: str, value: str) -> str:
        p = Path(value).expanduser()
        return str(p if p.is_absolute() else (path.parent / p).resolve())

    try:
        config = build(ScenarioConfig, data, resolve_path=resolve)
    except FieldError as err:
        raise ConfigError(f"{path}: {err}") from None
    return dataclasses.replace(config, path=str(path))


def landmarks_path(config: ScenarioConfig) -> Path:
    """The landmark map of a scenario (relative paths are relative to the scenario file)."""
    p = Path(config.landmarks)
    if p.is_absolute() or not config.path:
        return p
    return Path(config.path).parent / p
