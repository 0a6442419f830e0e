"""``companion calibrate noise``: the corner jitter of a landmark held still, measured by the
real perception on a rendered scene with a known added jitter, written as pixel_sigma_px."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.errors import InputError
from companion.noise import summarise
from companion.settings import load_settings
from tests.calibration.still import StillScene, camera_toml, still_scene, vehicle_toml


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> StillScene:
    return still_scene(tmp_path_factory.mktemp("still"), jitter_px=0.2)


def measure(tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str],
            extra: str = "", landmark: str = "wall-02") -> tuple[int, str, str, Path]:
    (tmp_path / "cam.toml").write_text(camera_toml(scene.camera))
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text(vehicle_toml(scene, "cam.toml", extra))
    out = tmp_path / "noise.toml"
    status = main(["--config", str(vehicle), "calibrate", "noise", "--landmark", landmark,
                   "--out", str(out)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err, out


def jitter_of(stdout: str) -> float:
    match = re.search(r"corner jitter ([0-9.]+) px", stdout)
    assert match, stdout
    return float(match.group(1))


def test_the_measured_jitter_is_the_added_one(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    """Every corner moves with the frame's offset, so the perception's corners jitter by the
    offsets drawn (plus its own, ~0.005 px on this scene without offsets)."""
    status, stdout, err, out = measure(tmp_path, scene, capsys)
    assert status == 0, err
    assert jitter_of(stdout) == pytest.approx(scene.jitter_px, rel=0.1)
    settings = load_settings([tmp_path / "vehicle.toml", out])  # a valid layer
    assert settings.pose.pixel_sigma_px == pytest.approx(jitter_of(stdout), abs=1e-4)
    assert settings.noise_measured  # the status no longer says "uncalibrated noise"


def test_the_value_written_undoes_the_perceptions_plate_size_law(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    """With the size law on, the perception states sigma x (100 px / width) ** 0.8 for this
    plate: the value written is the jitter divided by that, so the plate gets the jitter."""
    status, stdout, err, out = measure(tmp_path, scene, capsys,
                                       "[perception]\ncorner_sigma_exponent = 0.8\n")
    assert status == 0, err
    width = float(re.search(r"plate ([0-9]+) px wide", stdout).group(1))  # type: ignore[union-attr]
    written = load_settings([out]).pose.pixel_sigma_px
    assert written * (100.0 / width) ** 0.8 == pytest.approx(jitter_of(stdout), rel=0.01)


def test_a_landmark_not_seen_is_one_line_and_writes_nothing(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err, out = measure(tmp_path, scene, capsys, landmark="wall-01")
    assert status == 2
    assert err.strip().splitlines()[-1].startswith(
        "calibrate noise: landmark wall-01 had aligned corners in 0 of 90 frames")
    assert not out.exists()
    status, _, err, _ = measure(tmp_path, scene, capsys, landmark="nowhere")
    assert status == 2 and "no landmark 'nowhere'" in err


def test_a_moving_landmark_is_refused() -> None:
    quad = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 60.0], [0.0, 60.0]])
    corners = [quad + np.array([0.2 * i, 0.0]) for i in range(40)]  # 7.8 px first to last
    with pytest.raises(InputError, match=r"moved 3\.9 px"):
        summarise("a", 40, corners, [1.0] * 40)
