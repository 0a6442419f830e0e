"""``companion calibrate camera`` on boards rendered by the simulated camera with known
intrinsics and distortion: the truth is recovered, and bad sessions write nothing."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.calibration import BoardDetector
from companion.calibration_boards import BoardCamera, spread_views
from companion.cli import main
from companion.settings import load_settings
from testsupport.boards import (
    CHARUCO,
    CHESSBOARD,
    PX_PER_SQUARE,
    TRUTH,
    partial_session,
    session,
)


def calibrate(capsys: pytest.CaptureFixture[str], images: Path, out: Path, *extra: str
              ) -> tuple[int, str, str]:
    status = main(["calibrate", "camera", "--images", str(images), "--out", str(out), *extra])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_truth(out: Path, tolerance: float) -> None:
    camera = load_settings([out]).camera  # the file is a valid configuration layer
    for name in ("fx", "fy", "cx", "cy"):
        got, want = getattr(camera, name), getattr(TRUTH, name)
        assert abs(got - want) / want < tolerance, f"{name}: {got} vs {want}"
    assert (camera.width, camera.height) == (TRUTH.width, TRUTH.height)
    assert camera.distortion[0] == pytest.approx(TRUTH.distortion[0], abs=0.01)


def rms_of(stdout: str) -> float:
    match = re.search(r"RMS reprojection error ([0-9.]+) px", stdout)
    assert match, stdout
    return float(match.group(1))


def test_a_chessboard_session_recovers_the_camera(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cam.toml"
    status, stdout, err = calibrate(capsys, session(tmp_path / "views"), out)
    assert status == 0, err
    assert_truth(out, 0.003)  # focal length and principal point within 0.3 %
    assert rms_of(stdout) < 0.1
    assert "worst views: view_" in stdout
    assert "views kept" in err  # progress, frame by frame


def test_a_charuco_session_recovers_the_camera(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Area-sampled boards and marker-free refinement windows (docs/decisions.md)."""
    out = tmp_path / "cam.toml"
    status, stdout, err = calibrate(
        capsys, session(tmp_path / "views", "charuco"), out, "--board", "charuco",
        "--squares", "7x5", "--square-mm", "50", "--marker-mm", "35")
    assert status == 0, err
    assert_truth(out, 0.003)
    assert rms_of(stdout) < 0.1


def test_a_video_file_is_sampled(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    views = session(tmp_path / "views", count=20)
    video = tmp_path / "session.mkv"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"FFV1"), 4.0, (640, 480))
    for path in sorted(views.glob("*.png")):
        frame = cv2.imread(str(path))
        writer.write(frame)
        writer.write(frame)  # each view twice: --every-s 0.5 keeps one of the two
    writer.release()
    out = tmp_path / "cam.toml"
    status = main(["calibrate", "camera", "--video", str(video), "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert captured.err.count("frame ") == 20
    assert_truth(out, 0.003)


@pytest.mark.parametrize(("case", "message"), [
    ("blurred", "were blurred (edges wider than 4 px)"),
    ("partial", "no chessboard of 10x7 squares (30 mm) found in any of 16 frames"),
    ("absent", "no chessboard of 10x7 squares (30 mm) found in any of 12 frames"),
    ("centre", "of the image (need 60%): show the board in the corners"),
    ("few", "only 5 usable views (need 10)"),
])
def test_a_bad_session_is_one_line_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, message: str) -> None:
    folder = tmp_path / "views"
    if case == "blurred":
        session(folder, count=12, blur_sigma_px=2.0)
    elif case == "partial":
        partial_session(folder)
    elif case == "absent":
        session(folder, count=12, board=False)
    elif case == "centre":
        session(folder, count=20, seed=2, reach=0.1, distance_m=(0.9, 1.2))
    else:
        session(folder, count=5)
    out = tmp_path / "cam.toml"
    status, stdout, err = calibrate(capsys, folder, out)
    assert status == 2
    last = err.strip().splitlines()[-1]
    assert message in last, err
    assert last.startswith("calibrate: ") and "Traceback" not in err
    assert not out.exists() and stdout == ""


def test_an_existing_camera_file_is_not_replaced_silently(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cam.toml"
    out.write_text("# mine\n")
    status, _, err = calibrate(capsys, session(tmp_path / "views", count=12), out)
    assert status == 2 and "exists (use --overwrite" in err
    assert out.read_text() == "# mine\n"


@pytest.mark.parametrize("kind", ["chessboard", "charuco"])
def test_every_corner_is_found_where_the_board_puts_it(kind: str) -> None:
    """Against the rendered truth, corner by corner, on views tilted by up to 35 degrees all
    over the image (the ChArUco corners next to the markers' edges, too): no corner more
    than 0.2 px off (before marker-free windows and area-sampled boards: 2.6 px)."""
    spec = CHESSBOARD if kind == "chessboard" else CHARUCO
    cam = BoardCamera(TRUTH, spec, PX_PER_SQUARE[kind])
    detector = BoardDetector(spec)
    errors = []
    for view in spread_views(TRUTH, 16, seed=1):
        found = detector.find("view", cam.render(view))
        assert found is not None
        truth = cam.true_corners(view)  # the nearest: a chessboard's order may be turned
        for corner in found.image_points.reshape(-1, 2):
            errors.append(np.linalg.norm(truth - corner, axis=1).min())
    assert len(errors) > 16 * 12
    assert max(errors) < 0.2, f"worst corner {max(errors):.3f} px off"
