"""The ``companion`` command as a user runs it: a real subprocess."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from companion import __version__

ROOT = Path(__file__).resolve().parents[1]


def companion(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion", *args],
        cwd=cwd, capture_output=True, text=True, timeout=60, check=False,
    )


def test_version() -> None:
    out = companion("--version")
    assert out.returncode == 0
    assert out.stdout.strip() == f"companion {__version__}"


def test_help_lists_the_commands_that_exist() -> None:
    out = companion("--help")
    assert out.returncode == 0
    assert "config" in out.stdout
    assert "--set SECTION.KEY=VALUE" in out.stdout


def test_no_command_prints_help_and_fails() -> None:
    out = companion()
    assert out.returncode == 2
    assert "usage: companion" in out.stdout


def test_wrong_type_is_one_line_exit_2_no_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[camera]\nwidth = "wide"\n')
    out = companion("--config", str(bad), "config")
    assert out.returncode == 2
    assert out.stderr == f'{bad}: camera.width: expected an integer >= 1, got "wide"\n'
    assert out.stdout == ""


def test_unknown_key_is_one_line_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nfocal = 3\n")
    out = companion("config", "--config", str(bad))  # options also after the command
    assert out.returncode == 2
    assert out.stderr.startswith(f"{bad}: camera.focal: unknown key (expected one of: ")
    assert out.stderr.count("\n") == 1
    assert "Traceback" not in out.stderr


def test_relative_config_path_is_shown_as_given(tmp_path: Path) -> None:
    (tmp_path / "bad.toml").write_text("[vehicle]\nprofile = 'ardupilt'\n")
    out = companion("--config", "bad.toml", "config", cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr == (
        'bad.toml: vehicle.profile: expected one of "ardupilot", "px4", got "ardupilt"\n'
    )


def test_config_json_shows_overrides_and_files() -> None:
    out = companion("--set", "vehicle.id=drone7", "config", "--json")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["settings"]["vehicle"]["id"] == "drone7"
    assert data["files"][-1].endswith("ardupilot.toml")


def test_json_log_format_writes_json_lines(tmp_path: Path) -> None:
    script = (
        "import logging, sys\n"
        "from companion.logs import setup_logging\n"
        "setup_logging('json', 'info', sys.stdout)\n"
        "logging.getLogger('companion.x').info('hello %s', 'there', extra={'fps': 30})\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=30, check=True, cwd=ROOT)
    record = json.loads(out.stdout)
    assert record["msg"] == "hello there"
    assert record["level"] == "info"
    assert record["logger"] == "companion.x"
    assert record["fps"] == 30


def test_native_thread_pools_are_one_thread_unless_the_user_says_otherwise() -> None:
    """The pipeline runs its own threads; OpenBLAS/OpenMP pools on top oversubscribe the
    cores (docs/decisions.md).  Importing the package sets nothing; the entry point sets the
    limit before numpy loads, and a value the user exported is kept."""
    probe = ("import os, sys, companion, companion.launch as launch\n"
             "print(*(v in os.environ for v in launch.LIBRARY_THREAD_VARS))\n"
             "try:\n    launch.main(['--version'])\nexcept SystemExit:\n    pass\n"
             "print(*(os.environ[v] for v in launch.LIBRARY_THREAD_VARS))\n")
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=60, check=True)
    lines = out.stdout.splitlines()
    assert lines[0].split() == ["False", "False", "False"]  # importing set nothing
    assert lines[-1].split() == ["1", "1", "1"]
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         env={**env, "OMP_NUM_THREADS": "2"}, cwd=ROOT, timeout=60, check=True)
    assert out.stdout.splitlines()[-1].split() == ["1", "2", "1"]


def test_config_json_names_the_layer_that_set_each_key() -> None:
    out = companion("--set", "camera.fx=600", "config", "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    origins = doc["origins"]
    assert origins["camera.fx"] == "--set"
    assert origins["pose.pixel_sigma_px"] == "config/default.toml"
    assert origins["tracker.filter.particles"] == "built-in default"
    assert set(origins) >= {"vehicle.id", "camera.distortion", "source.follow.fps"}
    assert doc["noise"] == "uncalibrated"
    sim = json.loads(companion("config", "--sim", "--json").stdout)
    assert sim["origins"]["pose.pixel_sigma_px"] == "config/sim.toml"
    assert sim["origins"]["camera.fx"] == "config/cameras/sim-640x480.toml"
    assert sim["settings"]["pose"]["pixel_sigma_px"] == 0.07
    assert sim["noise"] == "measured"


BLOCK_IMPORTS = (
    "import sys\n"
    "class Block:\n"
    "    def find_spec(self, name, path=None, target=None):\n"
    "        if name.split('.')[0] in {blocked!r}:\n"
    "            raise ImportError(name=name)\n"
    "sys.meta_path.insert(0, Block())\n"
    "from companion.launch import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)


def without(blocked: set[str], *args: str) -> subprocess.CompletedProcess[str]:
    """``companion ARGS`` in a Python where the ``blocked`` packages cannot be imported."""
    return subprocess.run([sys.executable, "-c", BLOCK_IMPORTS.format(blocked=blocked), *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)


def test_a_missing_extra_is_one_line_naming_it(tmp_path: Path) -> None:
    """postgis, dashboard and mavsdk are extras: the rest works without them, and a feature
    that needs one names the extra to install."""
    extras = {"uvicorn", "starlette", "psycopg", "mavsdk"}
    assert without(extras, "--help").returncode == 0
    out = without(extras, "dashboard")
    assert out.returncode == 2
    assert out.stderr == ("companion dashboard needs the optional package uvicorn, which is "
                          "not installed: pip install 'landmark-companion[dashboard]'\n")
    out = without(extras, "landmarks", "--db", "postgresql://db/x", "list")
    assert "pip install 'landmark-companion[postgis]'" in out.stderr, out.stderr
    assert out.stderr.count("\n") == 1 and out.returncode == 2
    out = without(extras, "run", "--seconds", "1", "--set", "mavlink.backend=mavsdk",
                  "--set", "source.kind=sim", "--set", "source.spec=survey",
                  "--set", "monitor.enabled=false", "--set", "mavlink.origin_lat_deg=47.3769",
                  "--set", "mavlink.origin_lon_deg=8.5417", "--set", f'flightlog.dir="{tmp_path}"',
                  "--set", f'landmarks.map_path="{ROOT / "config" / "landmarks.geojson"}"')
    assert out.stderr.endswith("pip install 'landmark-companion[mavsdk]'\n"), out.stderr
    assert out.returncode == 2 and "Traceback" not in out.stderr
