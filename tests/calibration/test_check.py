"""``companion check`` against the fake autopilot and a recorded stream: one line per check,
exit status 1 on any failure, and each failure on its own line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.cli import main
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig
from mavlink_bridge.params import profile_parameters
from tests.calibration.still import StillScene, camera_toml, still_scene, vehicle_toml
from tests.follow.test_run_follow import fake_in_thread
from tracker.camera import CameraModel

#: What a 1280x720 camera's file says: the wrong file for this 640x480 stream.
WRONG = CameraModel(1280, 720, 1050.0, 1050.0, 639.5, 359.5)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> StillScene:
    return still_scene(tmp_path_factory.mktemp("still"), jitter_px=0.2, frames=40)


@pytest.fixture(scope="module")
def plain_scene(tmp_path_factory: pytest.TempPathFactory) -> StillScene:
    return still_scene(tmp_path_factory.mktemp("plain"), 0.0, frames=5, plain_signs=True)


def check(tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str], port: int,
          camera: CameraModel | None = None, *extra: str) -> tuple[int, dict[str, str]]:
    (tmp_path / "cam.toml").write_text(camera_toml(camera or scene.camera))
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text(vehicle_toml(scene, "cam.toml", endpoint=f"udpout:127.0.0.1:{port}"))
    status = main(["--config", str(vehicle), "check", "--link-timeout", "3", *extra])
    out = capsys.readouterr().out
    lines = {line.split(":", 1)[0].split(None, 1)[1]: line for line in out.splitlines()[:-1]}
    return status, lines


def test_a_good_set_up_passes(tmp_path: Path, scene: StillScene,
                              capsys: pytest.CaptureFixture[str]) -> None:
    with fake_in_thread(FakeAutopilotConfig(profile="ardupilot")) as fake:
        fake.params.values.update(profile_parameters("ardupilot", 35.0))  # as set up
        status, lines = check(tmp_path, scene, capsys, fake.local_port)
    assert status == 0, lines
    assert list(lines) == ["noise", "camera file", "camera", "landmarks", "link", "streams",
                           "parameters"]
    assert lines["noise"].startswith("warn  noise: uncalibrated noise")
    assert lines["camera"].startswith("pass  camera: ") and "640x480 at 30.0 fps" in lines["camera"]
    assert lines["landmarks"] == ("pass  landmarks: 4 in the map, each with a reference image "
                                  "the matcher accepts")
    assert lines["link"].startswith("pass  link: ") and "ArduPilot heartbeat" in lines["link"]
    assert lines["streams"].startswith("pass  streams: ATTITUDE ")
    assert lines["parameters"] == ("pass  parameters: 9 as the ardupilot profile wants "
                                   "(VISO_DELAY_MS 35 ms)")


def test_a_wrong_camera_file_fails_on_that_line(tmp_path: Path, scene: StillScene,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    with fake_in_thread(FakeAutopilotConfig(profile="ardupilot")) as fake:
        fake.params.values.update(profile_parameters("ardupilot", 35.0))
        status, lines = check(tmp_path, scene, capsys, fake.local_port, WRONG)
    assert status == 1
    assert lines["camera"].startswith("FAIL  camera: ")
    assert "frames are 640x480, the camera file" in lines["camera"]
    assert "says 1280x720" in lines["camera"]
    assert [n for n, line in lines.items() if line.startswith("FAIL")] == ["camera"]


def test_no_autopilot_and_the_wrong_autopilot_fail_the_link(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    status, lines = check(tmp_path, scene, capsys, 9)  # nobody answers on port 9
    assert status == 1
    assert lines["link"] == "FAIL  link: udpout:127.0.0.1:9: no autopilot heartbeat in 3 s"
    with fake_in_thread(FakeAutopilotConfig(profile="px4")) as fake:
        status, lines = check(tmp_path, scene, capsys, fake.local_port)
    assert status == 1
    assert lines["link"].endswith("the autopilot is PX4, vehicle.profile = ardupilot")


def test_intrinsics_of_another_resolution_fail(tmp_path: Path, scene: StillScene,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A 1280x720 calibration with only the size edited to 640x480."""
    edited = CameraModel(640, 480, 1050.0, 1050.0, 639.5, 359.5)
    status, lines = check(tmp_path, scene, capsys, 9, edited, "--link-timeout", "0.5")
    assert status == 1
    assert "far from the centre of a 640x480 image" in lines["camera file"]


def test_landmarks_the_matcher_cannot_find_fail(
        tmp_path: Path, plain_scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    status, lines = check(tmp_path, plain_scene, capsys, 9, None, "--link-timeout", "0.5")
    assert status == 1
    assert lines["landmarks"].startswith("FAIL  landmarks: sign-01's image has ")
    assert "sign-02's image has" in lines["landmarks"]


def test_a_flight_with_the_shipped_noise_says_uncalibrated(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    """companion run on the recorded stream: every status record of the flight log carries
    the noise's state, and the log warns while the shipped conservative value is in force."""
    (tmp_path / "cam.toml").write_text(camera_toml(scene.camera))
    vehicle = tmp_path / "vehicle.toml"
    with fake_in_thread(FakeAutopilotConfig(profile="ardupilot")) as fake:
        vehicle.write_text(vehicle_toml(scene, "cam.toml",
                                        endpoint=f"udpout:127.0.0.1:{fake.local_port}"))
        status = main(["--config", str(vehicle), "--set", f'flightlog.dir="{tmp_path}"',
                       "run", "--seconds", "2"])
    err = capsys.readouterr().err
    assert status == 0, err
    records = [json.loads(line) for log in tmp_path.glob("run-*.jsonl")
               for line in log.read_text().splitlines()]
    noise = {r.get("noise") for r in records if r["kind"] == "status"}
    assert noise == {"uncalibrated"}
    assert "uncalibrated noise: pose.pixel_sigma_px = 1 is the conservative default" in err


def test_the_shipped_defaults_fail_every_line_without_a_traceback(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No camera file, no camera 0 here, no EKF origin, nobody on the link: each is a line."""
    status = main(["--set", "source.spec=/dev/no-such-camera", "check", "--link-timeout", "0.5"])
    out, err = capsys.readouterr()
    assert status == 1 and "Traceback" not in err
    names = [line.split(":", 1)[0] for line in out.splitlines()[:-1]]
    assert names == ["warn  noise", "FAIL  camera file", "FAIL  camera", "FAIL  landmarks",
                     "FAIL  link", "FAIL  streams", "FAIL  parameters"]
    assert out.splitlines()[-1] == ("1 of 7 checks passed; failed: camera file, camera, "
                                    "landmarks, link, streams, parameters")


def test_an_autopilot_not_set_up_fails_parameters_and_a_missing_stream_fails_streams(
        tmp_path: Path, scene: StillScene, capsys: pytest.CaptureFixture[str]) -> None:
    """ArduPilot's own defaults (no external navigation: VISO_TYPE 0, GPS as the position
    source) and a range finder configured on an autopilot that has none: both lines fail,
    each naming what is wrong; the other lines still pass."""
    cfg = FakeAutopilotConfig(profile="ardupilot", absent=("DISTANCE_SENSOR",))
    with fake_in_thread(cfg) as fake:
        status, lines = check(tmp_path, scene, capsys, fake.local_port, None, "--set",
                              "pose.rangefinder=true")
    assert status == 1
    assert lines["link"].startswith("pass  link: ")
    assert lines["streams"].startswith("FAIL  streams: DISTANCE_SENSOR missing"), lines
    assert "ATTITUDE" not in lines["streams"]  # the streams that arrive are not listed
    assert lines["parameters"].startswith("FAIL  parameters: VISO_TYPE 0 (wants 1); ")
    assert "EK3_SRC1_POSXY 3 (wants 6)" in lines["parameters"]
    assert "VISO_DELAY_MS" not in lines["parameters"]  # any answer will do for the delay


def test_a_camera_off_its_asked_rate_warns() -> None:
    """``source.camera_fps`` asked 15 fps and the camera delivers 30: a warning naming
    both (the flight can go on; the driver keeps to its modes), 16 fps passes."""
    from companion.preflight import FrameSample, check_frames
    from companion.settings import load_settings

    settings = load_settings(sets=["source.spec=camera:0", "source.camera_fps=15"])
    size = (settings.camera.width, settings.camera.height)
    off = check_frames(settings, FrameSample(30, size, 30.0))
    assert off.verdict == "warn" and "at 30.0 fps, not the 15 fps source.camera_fps" \
        in off.detail, off
    assert check_frames(settings, FrameSample(30, size, 16.0)).verdict == "pass"
    unset = load_settings(sets=["source.spec=camera:0"])
    assert check_frames(unset, FrameSample(30, size, 30.0)).verdict == "pass"
    # a recording replayed with the vehicle's file: its rate is the recording's, no warning
    video = load_settings(sets=["source.spec=video:/tmp/x.mp4", "source.camera_fps=15"])
    assert check_frames(video, FrameSample(30, size, 30.0)).verdict == "pass"


def test_a_camera_rate_that_cannot_be_asked_is_a_config_error_naming_its_layer() -> None:
    from companion.config_checks import check_camera_rate
    from companion.errors import ConfigError
    from companion.settings import load_settings

    pipeline = "camera:v4l2src ! videoconvert ! appsink"
    with pytest.raises(ConfigError, match=r"source.camera_fps = 15 \(--set\).*framerate=15/1"):
        check_camera_rate(load_settings(sets=[f"source.spec={pipeline}",
                                              "source.camera_fps=15"]))
    check_camera_rate(load_settings(sets=["source.spec=camera:0", "source.camera_fps=15"]))
    check_camera_rate(load_settings(sets=["source.spec=stream:/tmp/s", "source.camera_fps=15"]))
