"""Configuration: TOML layers -> one frozen :class:`Settings`, loaded once at start-up.

Layers, later ones win (tables merge key by key, lists are replaced):

1. ``config/default.toml``: the deployment's defaults (a real camera, conservative noise);
   then the shipped layers a command asks for, e.g. ``config/sim.toml`` (the simulator's
   camera and the values calibrated on its rendered plates) for ``demo`` and ``synth``;
2. the vehicle profile ``config/<vehicle.profile>.toml`` (``ardupilot`` or ``px4``);
3. each ``--config FILE`` in order (a file may ``include = ["other.toml"]`` too);
4. each ``--set section.key=value`` in order (the value is read as a TOML value; a bare
   word is a string).

Every error is one line naming where the bad value came from, the key path and what was
expected, e.g. ``config/default.toml: tracker.filter.particles: expected an integer >= 4,
got "twenty"``.  Unknown keys are errors.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from companion.core.resources import config_dir
from companion.core.validate import FieldError, build
from companion.errors import ConfigError
from companion.fixgate import FixGateConfig
from companion.landmarks.config import LandmarksConfig
from companion.monitoring.config import MonitorConfig
from companion.perception import PerceptionConfig
from companion.sources.config import SourceConfig
from mavlink_bridge.config import MavlinkConfig
from tracker.acquire import AcquireConfig
from tracker.camera import CameraModel
from tracker.config import TrackerConfig
from tracker.detector import DetectorConfig
from tracker.pose.config import PoseConfig

PROFILES = ("ardupilot", "px4")
SET_SOURCE = "--set"
#: The origin of a key no layer set: the dataclass field's default.
BUILT_IN = "built-in default"
#: The key whose origin says whether the pixel noise was measured (docs/deploy.md).
NOISE_KEY = "pose.pixel_sigma_px"
#: The simulator's shipped layer (config/sim.toml), for commands that fly the simulator.
SIM_LAYERS = ("sim",)


@dataclass(frozen=True)
class VehicleConfig:
    """Which vehicle this companion flies on."""

    id: str = field(default="lmc1", metadata={"min_len": 1, "pattern": r"[A-Za-z0-9_-]+"})
    profile: Literal["ardupilot", "px4"] = "ardupilot"


@dataclass(frozen=True)
class LoggingConfig:
    """Log level and format (the command line's --log-format/--log-level win)."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["text", "json"] = "text"


@dataclass(frozen=True)
class FlightLogConfig:
    """Where the flight log goes (relative to the working directory), how often it syncs and
    the size at which it rotates to a new part (0: never)."""

    dir: str = field(default="flightlogs", metadata={"min_len": 1})
    fsync_interval_s: float = field(default=1.0, metadata={"gt": 0, "le": 10})
    max_file_mb: float = field(default=100.0, metadata={"ge": 0})


@dataclass(frozen=True)
class Settings:
    """The whole configuration: one frozen section per component."""

    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    camera: CameraModel = field(default_factory=CameraModel)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    source: SourceConfig = field(default_factory=SourceConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    acquire: AcquireConfig = field(default_factory=AcquireConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    pose: PoseConfig = field(default_factory=PoseConfig)
    fixgate: FixGateConfig = field(default_factory=FixGateConfig)
    landmarks: LandmarksConfig = field(default_factory=LandmarksConfig)
    mavlink: MavlinkConfig = field(default_factory=MavlinkConfig)
    monitor: MonitorConfig = field(default_factory=MonitorConfig)
    flightlog: FlightLogConfig = field(default_factory=FlightLogConfig)
    #: The files that were read, in order (set by the loader, not by users).
    config_files: tuple[str, ...] = field(default=(), metadata={"internal": True})
    #: (dotted key, the layer that set it) for every key a layer set (set by the loader).
    origins: tuple[tuple[str, str], ...] = field(default=(), metadata={"internal": True})
    #: The shipped default.toml as shown in ``config_files`` (set by the loader).
    default_file: str = field(default="", metadata={"internal": True})

    def origin_of(self, key: str) -> str:
        """Which layer set ``key`` (a file as shown, ``--set``) or :data:`BUILT_IN`."""
        return dict(self.origins).get(key, BUILT_IN)

    @property
    def noise_measured(self) -> bool:
        """False while ``pose.pixel_sigma_px`` is the shipped conservative default: the
        status then says "uncalibrated noise" (``companion calibrate noise`` measures it)."""
        return self.origin_of(NOISE_KEY) not in (BUILT_IN, self.default_file)


def display_path(path: Path) -> str:
    """A path as a user would type it: relative to the working directory when inside it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


@dataclass
class _Layers:
    """Merged raw data plus, for every leaf key, the source that set it."""

    data: dict[str, Any] = field(default_factory=dict)
    origin: dict[str, str] = field(default_factory=dict)
    base_dir: dict[str, Path] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def merge(self, data: Mapping[str, Any], source: str, base: Path, prefix: str = "") -> None:
        target = self.data
        for part in prefix.split(".") if prefix else []:
            target = target.setdefault(part, {})
        for key, value in data.items():
            path = f"{prefix}.{key}" if prefix else key
            if isinstance(value, Mapping) and isinstance(target.get(key, {}), dict):
                target.setdefault(key, {})
                self.origin.setdefault(path, source)
                self.merge(value, source, base, path)
            else:
                target[key] = value
                self.origin[path] = source
                self.base_dir[path] = base

    def source_of(self, key: str) -> str:
        key = key.split("[", 1)[0]
        while key:
            if key in self.origin:
                return self.origin[key]
            key = key.rpartition(".")[0]
        return self.files[-1] if self.files else SET_SOURCE


def _read_toml(path: Path) -> dict[str, Any]:
    shown = display_path(path)
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{shown}: cannot read: no such file") from None
    except OSError as err:
        raise ConfigError(f"{shown}: cannot read: {err.strerror}") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{shown}: invalid TOML: {err}") from None
    except UnicodeDecodeError as err:  # TOML is UTF-8 (a Latin-1 or UTF-16 file lands here)
        raise ConfigError(f"{shown}: not UTF-8 text (byte {err.start}: {err.reason}); "
                          "save the file as UTF-8") from None


def _load_file(layers: _Layers, path: Path, seen: tuple[Path, ...] = ()) -> None:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{display_path(path)}: include: the file includes itself")
    data = _read_toml(path)
    shown = display_path(path)
    includes = data.pop("include", [])
    if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
        raise ConfigError(f"{shown}: include: expected a list of file names, got {includes!r}")
    for name in includes:
        _load_file(layers, path.parent / name, (*seen, path))
    layers.files.append(shown)
    layers.merge(data, shown, path.parent)


def parse_set(item: str) -> tuple[str, Any]:
    """``section.key=value`` -> (dotted key, TOML value; a bare word is a string)."""
    key, sep, text = item.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise ConfigError(f"{SET_SOURCE} {item}: expected section.key=value")
    try:
        value = tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()
    return key, value


def _nest(key: str, value: Any) -> dict[str, Any]:
    head, _, rest = key.partition(".")
    return {head: _nest(rest, value) if rest else value}


def _gather(config_files: Sequence[Path], sets: Sequence[str], profile: str | None,
            shipped: Sequence[str]) -> _Layers:
    layers = _Layers()
    root = config_dir()
    _load_file(layers, root / "default.toml")
    for name in shipped:
        _load_file(layers, root / f"{name}.toml")
    if profile is not None:
        _load_file(layers, root / f"{profile}.toml")
    for path in config_files:
        _load_file(layers, Path(path))
    for item in sets:
        key, value = parse_set(item)
        layers.merge(_nest(key, value), SET_SOURCE, Path.cwd())
    return layers


def load_settings(config_files: Sequence[Path] = (), sets: Sequence[str] = (),
                  shipped: Sequence[str] = ()) -> Settings:
    """Read, merge and validate every layer; raise ConfigError with one clear line.

    ``shipped``: names of shipped layers read right after default.toml (``("sim",)`` for
    the simulator's: ``companion demo``, ``synth`` and the scenario tests).
    """
    layers = _gather(config_files, sets, None, shipped)
    profile = layers.data.get("vehicle", {}).get("profile", PROFILES[0])
    if profile in PROFILES and (config_dir() / f"{profile}.toml").is_file():
        layers = _gather(config_files, sets, profile, shipped)

    def resolve(key: str, value: str) -> str:
        base = layers.base_dir.get(key.split("[", 1)[0], Path.cwd())
        return str((base / os.path.expanduser(value)).resolve())

    try:
        settings = build(Settings, layers.data, resolve_path=resolve)
    except FieldError as err:
        raise ConfigError(f"{layers.source_of(err.key)}: {err.key}: {err.message}") from None
    return dataclasses.replace(
        settings, config_files=tuple(layers.files),
        default_file=display_path(config_dir() / "default.toml"),
        origins=tuple((key, source) for key, source in layers.origin.items()
                      if key in layers.base_dir))
