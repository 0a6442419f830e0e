"""Configuration layering, validation and the one-line errors."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from companion.core.validate import FieldError, build, describe
from companion.errors import ConfigError
from companion.settings import BUILT_IN, SIM_LAYERS, load_settings, parse_set


@dataclass(frozen=True)
class Inner:
    rate_hz: float = field(default=10.0, metadata={"gt": 0, "le": 50})


@dataclass(frozen=True)
class Example:
    particles: int = field(default=20, metadata={"ge": 4})
    mode: Literal["a", "b"] = "a"
    flag: bool = False
    weights: tuple[float, ...] = (1.0,)
    pair: tuple[int, int] = (1, 2)
    gains: tuple[float, float] = field(default=(1.0, 1.0), metadata={"gt": 0})
    model: str = field(default="", metadata={"path": True})
    inner: Inner = Inner()


def test_build_accepts_good_values_and_converts_ints_to_floats() -> None:
    cfg = build(Example, {"particles": 30, "weights": [1, 2.5], "inner": {"rate_hz": 20}})
    assert cfg.particles == 30
    assert cfg.weights == (1.0, 2.5)
    assert isinstance(cfg.inner.rate_hz, float) and cfg.inner.rate_hz == 20.0
    assert cfg.mode == "a"  # default kept


@pytest.mark.parametrize(
    ("data", "key", "message"),
    [
        ({"particles": "twenty"}, "particles", 'expected an integer >= 4, got "twenty"'),
        ({"particles": 3}, "particles", "expected an integer >= 4, got 3"),
        ({"particles": 4.5}, "particles", "expected an integer >= 4, got 4.5"),
        ({"particles": True}, "particles", "expected an integer >= 4, got true"),
        ({"mode": "c"}, "mode", 'expected one of "a", "b", got "c"'),
        ({"flag": 1}, "flag", "expected true or false, got 1"),
        ({"weights": [1, "x"]}, "weights[1]", 'expected a number, got "x"'),
        ({"pair": [1]}, "pair", "expected a list of 2 integers, got [1]"),
        ({"gains": [1]}, "gains", "expected a list of 2 numbers > 0, got [1]"),
        ({"gains": [1, 0]}, "gains[1]", "expected a number > 0, got 0"),
        ({"inner": {"rate_hz": 0}}, "inner.rate_hz", "expected a number > 0 and <= 50, got 0"),
        ({"inner": 5}, "inner", "expected a table, got 5"),
        ({"partciles": 5}, "partciles", "unknown key (expected one of: flag, gains, "
         "inner, mode, model, pair, particles, weights)"),
        ({"inner": {"rate": 5}}, "inner.rate", "unknown key (expected one of: rate_hz)"),
    ],
)
def test_build_rejects_bad_values_naming_key_and_expectation(
    data: dict[str, object], key: str, message: str
) -> None:
    with pytest.raises(FieldError) as info:
        build(Example, data)
    assert info.value.key == key
    assert info.value.message == message


def test_path_fields_are_resolved_by_the_callback() -> None:
    cfg = build(Example, {"model": "m.onnx"}, resolve_path=lambda key, v: f"/base/{key}/{v}")
    assert cfg.model == "/base/model/m.onnx"


def test_describe_tuple_of_numbers() -> None:
    assert describe(tuple[float, ...]) == "a list of numbers"


def test_defaults_load_and_the_profile_layer_applies() -> None:
    settings = load_settings()
    assert settings.vehicle.profile == "ardupilot"
    assert settings.camera.width == 640
    assert any(f.endswith("ardupilot.toml") for f in settings.config_files)
    px4 = load_settings(sets=["vehicle.profile=px4"])
    assert px4.vehicle.profile == "px4"
    assert any(f.endswith("px4.toml") for f in px4.config_files)


def test_config_file_then_set_override_in_order(tmp_path: Path) -> None:
    user = tmp_path / "user.toml"
    user.write_text('[vehicle]\nid = "alpha"\n[camera]\nfx = 400.0\n')
    settings = load_settings([user], ["camera.fx=410", "vehicle.id=beta"])
    assert settings.camera.fx == 410.0
    assert settings.vehicle.id == "beta"
    assert settings.camera.fy == 525.0  # untouched keys keep the default


def test_include_is_relative_to_the_including_file(tmp_path: Path) -> None:
    (tmp_path / "cam.toml").write_text("[camera]\nwidth = 1280\nheight = 720\n")
    main = tmp_path / "main.toml"
    main.write_text('include = ["cam.toml"]\n[camera]\nheight = 800\n')
    settings = load_settings([main])
    assert (settings.camera.width, settings.camera.height) == (1280, 800)


def test_error_names_the_file_that_set_the_bad_value(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[camera]\nfx = "wide"\n')
    with pytest.raises(ConfigError) as info:
        load_settings([bad])
    assert str(info.value) == f'{bad}: camera.fx: expected a number > 0, got "wide"'


def test_error_from_set_names_set() -> None:
    with pytest.raises(ConfigError) as info:
        load_settings(sets=["vehicle.id=has space"])
    assert str(info.value).startswith("--set: vehicle.id: expected a string matching")


def test_unknown_section_is_an_error(tmp_path: Path) -> None:
    bad = tmp_path / "typo.toml"
    bad.write_text("[vehicel]\nid = 'x'\n")
    with pytest.raises(ConfigError, match=r"typo.toml: vehicel: unknown key"):
        load_settings([bad])


@pytest.mark.parametrize(
    ("text", "message"),
    [("[camera\n", "invalid TOML"), (None, "cannot read: no such file")],
)
def test_unreadable_files_give_one_line(tmp_path: Path, text: str | None, message: str) -> None:
    path = tmp_path / "c.toml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_settings([path])
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_include_cycle_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "loop.toml"
    path.write_text('include = ["loop.toml"]\n')
    with pytest.raises(ConfigError, match="includes itself"):
        load_settings([path])


@pytest.mark.parametrize(
    ("item", "key", "value"),
    [("a.b=3", "a.b", 3), ("a.b=word", "a.b", "word"), ('a.b="3"', "a.b", "3"),
     ("a.b=[1, 2]", "a.b", [1, 2]), ("a.b=true", "a.b", True)],
)
def test_parse_set_reads_toml_values(item: str, key: str, value: object) -> None:
    assert parse_set(item) == (key, value)


@pytest.mark.parametrize("item", ["novalue", "=3", "a..b=1"])
def test_parse_set_rejects_malformed(item: str) -> None:
    with pytest.raises(ConfigError, match=r"expected section\.key=value"):
        parse_set(item)


def test_the_deployment_defaults_are_not_the_simulators() -> None:
    """default.toml is the deployment's: a real camera, the solver library's conservative
    noise (status "uncalibrated noise"); the simulator's calibrated values are in sim.toml."""
    deploy = load_settings()
    assert (deploy.source.kind, deploy.source.spec) == ("camera", "0")
    assert deploy.pose.pixel_sigma_px == 1.0
    assert deploy.perception.corner_sigma_exponent == 0.0
    assert not deploy.pose.learn_attitude_bias  # a real autopilot's attitude error: unmeasured
    assert not deploy.noise_measured
    assert not any("sim" in Path(f).name for f in deploy.config_files)
    assert deploy.origin_of("camera.fx") == BUILT_IN
    sim = load_settings(shipped=SIM_LAYERS)
    assert sim.source.kind == "sim"
    assert sim.pose.pixel_sigma_px == 0.07
    assert sim.perception.corner_sigma_exponent == 1.4
    assert sim.pose.learn_attitude_bias  # the simulated autopilots' Gauss-Markov error
    assert sim.camera.mount_rpy_deg == (0.0, -30.0, 0.0)
    assert sim.noise_measured
    assert sim.origin_of("pose.pixel_sigma_px").endswith("config/sim.toml")


def test_a_measured_noise_in_the_users_file_is_measured(tmp_path: Path) -> None:
    noise = tmp_path / "noise.toml"
    noise.write_text("[pose]\npixel_sigma_px = 0.4\n")
    settings = load_settings([noise])
    assert settings.noise_measured
    assert settings.origin_of("pose.pixel_sigma_px") == str(noise)
    assert settings.origin_of("vehicle.id").endswith("config/default.toml")


def test_the_sitl_configs_fly_the_simulators_layer() -> None:
    root = Path(__file__).resolve().parents[1] / "config"
    for name in ("sitl-ardupilot.toml", "sitl-px4.toml"):
        settings = load_settings([root / name])
        assert settings.pose.pixel_sigma_px == 0.07, name
        assert settings.source.kind == "follow", name


def test_a_flat_tracker_key_says_where_it_moved(tmp_path: Path) -> None:
    """The [tracker] keys are grouped in tables (docs/decisions.md): an old flat key is
    not just unknown, the error names its new place."""
    old = tmp_path / "old.toml"
    old.write_text("[tracker]\nparticles = 30\n")
    with pytest.raises(ConfigError) as info:
        load_settings([old])
    assert str(info.value) == f"{old}: tracker.particles: moved to tracker.filter.particles"
    new = tmp_path / "new.toml"
    new.write_text("[tracker.filter]\nparticles = 30\n")
    assert load_settings([new]).tracker.filter.particles == 30
