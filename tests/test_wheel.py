"""The wheel works outside the checkout (issue 20): built from a copy of the sources,
installed into a fresh virtual environment, and run from an empty directory.  The
extras (postgis, dashboard, mavsdk) are not needed by anything run here.

The fresh environment gets the wheel with ``--no-deps --no-index``; its dependencies come
from this (dev) environment's site-packages through a ``.pth`` path line, so nothing is
downloaded (a plain path line adds the folder without running its ``.pth`` files: the
editable install of the checkout stays invisible).  ``pip check`` then proves the wheel's
declared dependencies are all satisfied.  Building the wheel uses pip's build isolation
(setuptools and wheel from the package index or pip's cache).
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import sysconfig
import time
import venv
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.calibration.still import camera_toml, still_scene, vehicle_toml
from testsupport.boards import TRUTH, session
from tracker.camera import CameraModel

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "setup.py", "README.md", "companion", "tracker", "mavlink_bridge",
           "fieldbounds", "config")


def run(*cmd: str | Path, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {"PATH": "/usr/bin:/bin", "HOME": str(cwd)}  # no PYTHONPATH, no checkout
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout, check=False)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The ``bin`` folder of a fresh venv holding the wheel."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            src.mkdir(exist_ok=True)
            shutil.copy2(path, src / name)
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                            "-w", str(tmp / "dist"), str(src)],
                           capture_output=True, text=True, timeout=600, check=False)
    assert built.returncode == 0, built.stderr[-3000:]
    wheel = next((tmp / "dist").glob("landmark_companion-*.whl"))
    env = tmp / "venv"
    venv.EnvBuilder(with_pip=True).create(env)
    site = Path(run(env / "bin" / "python", "-c",
                    "import sysconfig; print(sysconfig.get_paths()['purelib'])",
                    cwd=tmp).stdout.strip())
    (site / "dev-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    out = run(env / "bin" / "python", "-m", "pip", "install", "--quiet", "--no-deps",
              "--no-index", wheel, cwd=tmp)
    assert out.returncode == 0, out.stderr
    out = run(env / "bin" / "python", "-m", "pip", "check", cwd=tmp)  # (the test tools'
    # own unmet requirements are known: requirements/tools.lock installs them --no-deps)
    ours = [line for line in out.stdout.splitlines() if line.startswith("landmark-companion")]
    assert not ours, out.stdout
    yield env / "bin"


@pytest.fixture
def empty(tmp_path: Path) -> Path:
    folder = tmp_path / "empty"
    folder.mkdir()
    return folder


def test_the_installed_package_is_the_wheels_and_reads_its_own_config(
        installed: Path, empty: Path) -> None:
    probe = ("import companion, companion.core.resources as r; "
             "print(companion.__file__); print(r.config_dir())")
    out = run(installed / "python", "-c", probe, cwd=empty)
    assert out.returncode == 0, out.stderr
    for line in out.stdout.split():
        assert line.startswith(str(installed.parent)), out.stdout  # not the checkout
    out = run(installed / "companion", "config", "--json", cwd=empty)
    assert out.returncode == 0, out.stderr
    files = json.loads(out.stdout)["files"]
    assert files and all(f.startswith(str(installed.parent)) for f in files), files


def test_demo_from_an_empty_directory(installed: Path, empty: Path) -> None:
    out = run(installed / "companion", "demo", "--seconds", "3", "--json", cwd=empty)
    assert out.returncode == 0, out.stderr[-3000:]
    assert json.loads(out.stdout)["frames"] > 0  # (the survey's landmarks come later)
    out = run(installed / "companion", "demo", "--scenario", "hover", "--seconds", "3",
              "--json", cwd=empty)
    assert out.returncode == 0, out.stderr[-3000:]
    summary = json.loads(out.stdout)
    assert summary["fixes_sent"] > 0, summary
    assert summary["fixes_accepted"] == summary["fixes_sent"]


def test_calibrate_on_rendered_boards(installed: Path, empty: Path, tmp_path: Path) -> None:
    views = session(tmp_path / "views", count=20)
    out = run(installed / "companion", "calibrate", "camera", "--images", views,
              "--out", "cam.toml", cwd=empty)
    assert out.returncode == 0, out.stderr[-3000:]
    text = (empty / "cam.toml").read_text()
    fx = float(text.split("fx = ", 1)[1].split()[0])
    assert abs(fx - TRUTH.fx) / TRUTH.fx < 0.003


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_check_against_the_fake_autopilot_and_a_recorded_stream(
        installed: Path, empty: Path, tmp_path: Path) -> None:
    scene = still_scene(tmp_path / "scene", 0.2, frames=40)
    port = free_udp_port()
    fake = subprocess.Popen([str(installed / "companion"), "fake-autopilot", "--endpoint",
                             f"udpin:127.0.0.1:{port}", "--seconds", "60"], cwd=empty,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(1.0)
        setup = run(installed / "companion", "autopilot", "setup", "--profile", "ardupilot",
                    "--endpoint", f"udpout:127.0.0.1:{port}", "--yes", "--delay-ms", "35",
                    cwd=empty)  # the walk of docs/deploy.md: set up, then check
        assert setup.returncode == 0, setup.stdout + setup.stderr
        results = {}
        for name, camera in (("good", scene.camera),
                             ("wrong", CameraModel(1280, 720, 1050.0, 1050.0, 639.5, 359.5))):
            (empty / f"{name}-cam.toml").write_text(camera_toml(camera))
            (empty / f"{name}.toml").write_text(
                vehicle_toml(scene, f"{name}-cam.toml", endpoint=f"udpout:127.0.0.1:{port}"))
            results[name] = run(installed / "companion", "--config", f"{name}.toml", "check",
                                cwd=empty)
    finally:
        fake.terminate()
        fake.wait(10)
    good, wrong = results["good"], results["wrong"]
    assert good.returncode == 0, good.stdout + good.stderr
    assert wrong.returncode == 1, wrong.stdout + wrong.stderr
    failed = [line for line in wrong.stdout.splitlines() if line.startswith("FAIL")]
    assert len(failed) == 1 and failed[0].startswith("FAIL  camera: "), wrong.stdout
    assert "the camera file (wrong-cam.toml) says 1280x720" in failed[0]
