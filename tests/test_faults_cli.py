"""Issue 24, faults: every error a user can cause is one line and a documented exit status
(docs/reliability.md), never a traceback, and never a silent success."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from companion.cli import main
from companion.flightlog import FlightLogWriter
from tests.faultkit import (
    FLIGHT,
    ROOT,
    companion_process,
    one_line_failure,
    plain_directory,
    remount_read_only,
    small_filesystem,
)

SAMPLE_MAP = ROOT / "config" / "landmarks.geojson"


def a_file(tmp_path: Path) -> Path:
    """A regular file: a path *under* it can be neither created nor written."""
    path = tmp_path / "plain-file"
    path.write_text("x")
    return path


# ---------------------------------------------------------------- configuration: status 2

def test_a_configuration_file_that_is_not_utf8_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "latin1.toml"
    bad.write_bytes('[vehicle]\nid = "caf\xe9"\n'.encode("latin-1"))
    line = one_line_failure(capsys, ["--config", str(bad), "config"], 2)
    assert "latin1.toml" in line and "UTF-8" in line


@pytest.mark.parametrize("value", ["inf", "-inf", "nan"])
def test_a_number_that_is_not_finite_is_refused(
        value: str, capsys: pytest.CaptureFixture[str]) -> None:
    line = one_line_failure(capsys, ["--set", f"camera.fx={value}", "config"], 2)
    assert "camera.fx" in line and "finite" in line


@pytest.mark.parametrize("command", ["run", "demo", "synth", "monitor", "router", "record"])
@pytest.mark.parametrize("seconds", ["-5", "0", "inf", "nan"])
def test_seconds_must_be_a_finite_positive_number(
        command: str, seconds: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main([command, "--seconds", seconds])
    assert stop.value.code == 2
    assert "--seconds: expected a finite number > 0" in capsys.readouterr().err


def test_an_unwritable_flightlog_dir_is_refused_before_anything_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    logs = a_file(tmp_path) / "logs"
    for command in (["config"], ["run", "--seconds", "1"], ["demo", "--seconds", "1"]):
        line = one_line_failure(capsys, [*FLIGHT, "--set", f'flightlog.dir="{logs}"',
                                         *command], 2)
        assert line.startswith("flightlog.dir: ") and "not a directory" in line
    assert not logs.exists()


def test_a_flightlog_dir_on_a_read_only_file_system_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with small_filesystem(tmp_path / "ro", 64) as mounted:
        if mounted is None:
            pytest.skip("needs a tmpfs (root); the not-a-directory case covers the rest")
        remount_read_only(mounted)
        line = one_line_failure(capsys, [*FLIGHT, "--set", f'flightlog.dir="{mounted}/logs"',
                                         "run", "--seconds", "1"], 2)
    assert "read-only file system" in line


# ---------------------------------------------------------------- the landmark database

@pytest.mark.parametrize("action", [["list"], ["show", "x"], ["export", "out.geojson"],
                                    ["score"], ["select", "--area", "circle:47.4,8.5,500"]])
def test_a_database_typo_is_one_line_and_creates_nothing(
        action: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    typo = tmp_path / "landmraks.db"
    line = one_line_failure(capsys, ["landmarks", "--db", str(typo), *action], 2)
    assert line == f"{typo}: no such landmark database (companion landmarks import creates one)"
    assert list(tmp_path.iterdir()) == []


def test_sync_from_a_typo_creates_neither_database(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = one_line_failure(capsys, ["landmarks", "--db", str(tmp_path / "board.db"), "sync",
                                     "--from", str(tmp_path / "clod.db"),
                                     "--area", "circle:47.4,8.5,500"], 2)
    assert "clod.db: no such landmark database" in line
    assert list(tmp_path.iterdir()) == []


def test_a_read_only_landmark_database_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with small_filesystem(tmp_path / "ro", 512) as mounted:
        where = mounted or tmp_path
        db = where / "lm.db"
        assert main(["landmarks", "--db", str(db), "import", str(SAMPLE_MAP)]) == 0
        capsys.readouterr()
        if mounted is not None:
            remount_read_only(mounted)
        else:  # not root: the permission bits hold
            db.chmod(0o444)
            where.chmod(0o555)
        try:
            line = one_line_failure(capsys, ["landmarks", "--db", str(db), "import",
                                             "--replace", str(SAMPLE_MAP)], 1)
        finally:
            if mounted is None:
                where.chmod(0o755)
    assert line.startswith(f"{db}: ")
    # not root: "attempt to write a readonly database"; a read-only mount: the WAL's shared
    # memory file cannot be created, "unable to open database file"
    assert "readonly database" in line or "unable to open database file" in line, line


@pytest.mark.parametrize("limit", ["tmpfs", "rlimit"])
def test_a_full_disk_during_import_is_one_line_and_leaves_the_database_as_it_was(
        limit: str, tmp_path: Path) -> None:
    with small_filesystem(tmp_path / "small", 40) if limit == "tmpfs" \
            else plain_directory(tmp_path / "plain") as where:
        if where is None:
            pytest.skip("no tmpfs here (not root); the rlimit case runs instead")
        db = where / "lm.db"
        out = companion_process("landmarks", "--db", str(db), "import", str(SAMPLE_MAP),
                                cwd=tmp_path,
                                max_file_bytes=20_000 if limit == "rlimit" else None)
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 1, out.stderr
        assert len(lines) == 1 and "Traceback" not in out.stderr, lines
        assert str(db) in lines[0]
        assert "full" in lines[0] or "I/O" in lines[0], lines[0]



# ---------------------------------------------------------------- output files: status 1

def test_log_export_to_an_unwritable_path_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = FlightLogWriter(tmp_path / "f.jsonl", "v1")
    log.write("fix", 1)
    log.close()
    out = a_file(tmp_path) / "out.csv"
    line = one_line_failure(capsys, ["log", "export", str(log.path), "--out", str(out)], 1)
    assert line == f"{out}: Not a directory"


def test_synth_to_an_unwritable_path_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = a_file(tmp_path) / "stream"
    line = one_line_failure(capsys, ["synth", "--scenario", "survey", "--seconds", "0.2",
                                     "--out", str(out)], 1)
    assert str(out) in line and "Not a directory" in line


# ---------------------------------------------------------------- interrupted: 130 / 143

def test_sigterm_during_a_plain_command_unwinds_and_exits_143(tmp_path: Path) -> None:
    """``synth`` has no event loop of its own: SIGTERM still unwinds it (``finally`` runs)
    and the status is 143, not a death by signal (-15) or a traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "companion", "synth", "--scenario", "survey",
                             "--seconds", "60", "--out", str(tmp_path / "s")], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (tmp_path / "s").exists():  # rendering has started
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.1)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert "Traceback" not in err


# ---------------------------------------------------------------- the autopilot link

@pytest.mark.parametrize(("setting", "says"), [
    ("mavlink.endpoint=garbage", "mavlink.endpoint: endpoint 'garbage': expected"),
    ("mavlink.endpoint=/dev/ttyNO-SUCH-DEVICE:57600",
     "mavlink.endpoint: serial device /dev/ttyNO-SUCH-DEVICE: No such file or directory"),
    ("mavlink.endpoint=/etc/hostname,57600",
     "mavlink.endpoint: /etc/hostname is not a serial device"),
    ('mavlink.signing_key_file="/no/such.key"',
     "mavlink.signing_key_file: signing key file /no/such.key: No such file or directory"),
])
@pytest.mark.parametrize("command", [["config"], ["run", "--seconds", "1"]])
def test_what_the_link_names_is_checked_before_anything_opens(
        setting: str, says: str, command: list[str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    line = one_line_failure(capsys, [*FLIGHT, "--set", f'flightlog.dir="{tmp_path}"',
                                     "--set", setting, *command], 2)
    assert line.startswith(says), line
    assert list(tmp_path.iterdir()) == []  # no flight log: nothing was opened


def test_a_port_in_use_is_one_line_and_status_1(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        line = one_line_failure(capsys, [*FLIGHT, "--set", f'flightlog.dir="{tmp_path}"',
                                         "--set", f"mavlink.endpoint=udpin:127.0.0.1:{port}",
                                         "run", "--seconds", "5"], 1)
    assert line == f"mavlink: udpin:127.0.0.1:{port}: Address already in use"
    assert list(tmp_path.iterdir()) == []  # no empty flight log per (re)start attempt


def test_a_frame_source_that_fails_for_good_exits_1(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every frame unreadable, looping: the run stops with status 1 (systemd's
    Restart=on-failure restarts it), not 0."""
    stream = tmp_path / "stream"
    assert main(["synth", "--scenario", "survey", "--seconds", "0.3", "--out",
                 str(stream)]) == 0
    frames = sorted(stream.rglob("*.png"))
    assert frames
    for frame in frames:
        frame.write_bytes(b"not a png")
    capsys.readouterr()
    status = main(["--log-level", "error", *FLIGHT, "--set", f'flightlog.dir="{tmp_path}/l"',
                   "--set", "source.kind=stream", "--set", f'source.spec="{stream}"',
                   "--set", "source.loop=true", "--set", "source.realtime=false",
                   "run", "--seconds", "30"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1, err
    assert err[-1].startswith("frame source failed: no readable frame in a whole pass"), err
    assert not any("Traceback" in line for line in err)


@pytest.mark.parametrize("command", [["config"], ["run", "--seconds", "1"]])
@pytest.mark.parametrize(("spec", "says"), [
    ("camera:v4l2src ! videoconvert ! appsink", "framerate=15/1"),
    ("camera:rtsp://127.0.0.1:8554/cam", "set where it is sent"),
])
def test_a_camera_rate_that_cannot_be_asked_is_one_line_before_anything_opens(
        spec: str, says: str, command: list[str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    line = one_line_failure(capsys, [*FLIGHT, "--set", f'flightlog.dir="{tmp_path}"',
                                     "--set", f'source.spec="{spec}"',
                                     "--set", "source.camera_fps=15", *command], 2)
    assert line.startswith("source.camera_fps = 15 (--set): ") and says in line, line
    assert list(tmp_path.iterdir()) == []  # refused before the flight log or the camera
