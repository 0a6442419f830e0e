"""``companion calibrate camera --camera``: the live path, with a stand-in camera that
delivers rendered boards in real time (tests/calibration/live.py).  What only a real camera
can show (its driver, exposure, rolling shutter, a person's hands) is in docs/deploy.md."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from companion import calibration_io
from companion.cli import main
from tests.calibration.live import LiveBoardCamera, live_camera
from tests.calibration.test_calibrate import assert_truth


def run_live(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
             camera: LiveBoardCamera, out: Path, *extra: str) -> tuple[int, str, str, float]:
    monkeypatch.setattr(calibration_io, "open_capture", camera.open)
    start = time.monotonic()
    status = main(["calibrate", "camera", "--camera", "0", "--out", str(out), *extra])
    elapsed = time.monotonic() - start
    captured = capsys.readouterr()
    return status, captured.out, captured.err, elapsed


def verdicts(err: str) -> list[str]:
    return re.findall(r"^calibrate: frame \d+ \([0-9.]+ of [0-9.]+ s\): ([a-z ]+)", err,
                      re.MULTILINE)


def test_a_live_session_picks_sharp_new_views_and_stops_when_it_has_enough(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    """16 poses, each held 0.3 s then moved (blurred) for 0.1 s: one look every 0.1 s keeps
    each pose once, refuses the moving board and the poses seen again, and stops at the
    14th view (--max-views), before the time limit."""
    camera = live_camera(16)
    out = tmp_path / "cam.toml"
    status, stdout, err, elapsed = run_live(
        monkeypatch, capsys, camera, out, "--every-s", "0.1", "--seconds", "120",
        "--max-views", "14")
    assert status == 0, err
    assert camera.targets == [0] and camera.released  # device 0, closed before the fit
    seen = verdicts(err)
    assert seen.count("kept") == 14
    assert any(v.startswith("blurred") for v in seen)
    assert "like a view already kept" in seen  # the same pose looked at again
    assert "calibrated on 14 views" in stdout
    assert elapsed < 100, f"{elapsed:.1f} s: it should stop once 14 views are kept"
    assert_truth(out, 0.003)


def test_a_live_session_stops_at_its_time_limit_with_one_line(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    """Four poses in 2.5 s: the session ends at --seconds and says why nothing was
    written (how many of the four poses are looked at depends on the machine's speed)."""
    camera = live_camera(4)
    out = tmp_path / "cam.toml"
    status, stdout, err, elapsed = run_live(
        monkeypatch, capsys, camera, out, "--every-s", "0.1", "--seconds", "2.5")
    assert status == 2
    assert 2.5 <= elapsed < 10
    last = err.strip().splitlines()[-1]
    kept = verdicts(err).count("kept")
    assert 1 <= kept <= 4
    assert last.startswith(f"calibrate: only {kept} usable views (need 10)"), err
    assert last.endswith("(the camera stopped at --seconds 2.5: allow longer)")
    assert not out.exists() and stdout == ""


@pytest.mark.parametrize(("opened", "fail_after", "message"), [
    (False, None, "calibrate: cannot open camera 0"),
    (True, 20, "calibrate: camera 0 stopped delivering frames"),
])
def test_a_camera_that_fails_is_one_line(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path,
        opened: bool, fail_after: int | None, message: str) -> None:
    camera = live_camera(2, fail_after=fail_after)
    camera.opened = opened
    out = tmp_path / "cam.toml"
    status, stdout, err, _ = run_live(monkeypatch, capsys, camera, out, "--seconds", "30")
    assert status == 2
    assert err.strip().splitlines()[-1] == message and "Traceback" not in err
    assert not out.exists() and stdout == ""
