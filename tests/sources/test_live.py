"""Video files, live cameras (with a fake capture) and the source factory."""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from companion import simulated
from companion.errors import ConfigError, InputError, SourceError
from companion.sources.base import EndOfStream
from companion.sources.config import SourceConfig
from companion.sources.factory import guess_kind, open_source, resolve, split_spec
from companion.sources.live import CameraSource, SourceStallError, VideoFileSource, camera_target


def write_video(path: Path, n: int, fps: float = 25.0) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (64, 48))
    assert writer.isOpened()
    for i in range(n):
        writer.write(np.full((48, 64, 3), 20 * i, np.uint8))
    writer.release()


async def test_video_file_frames_times_and_loop(tmp_path: Path) -> None:
    write_video(tmp_path / "v.avi", 4)
    source = VideoFileSource(tmp_path / "v.avi", realtime=False, loop=True)
    frames = [await source.recv() for _ in range(6)]
    source.close()
    assert [f.index for f in frames] == [0, 1, 2, 3, 4, 5]
    assert [f.t_us for f in frames[:3]] == [0, 40_000, 80_000] and frames[4].t_us == 160_000
    assert abs(float(frames[2].image.mean()) - 40) < 3
    assert np.array_equal(frames[4].image, frames[0].image)
    assert source.status.loops == 1
    assert all(f.lossy for f in frames)


async def test_video_file_ends_and_bad_files_are_one_line_errors(tmp_path: Path) -> None:
    write_video(tmp_path / "v.avi", 2)
    source = VideoFileSource(tmp_path / "v.avi", realtime=False)
    await source.recv()
    await source.recv()
    with pytest.raises(EndOfStream):
        await source.recv()
    source.close()
    with pytest.raises(InputError, match="does not exist"):
        VideoFileSource(tmp_path / "missing.mp4")
    (tmp_path / "junk.mp4").write_bytes(b"not a video at all")
    with pytest.raises(InputError, match="cannot open"):
        VideoFileSource(tmp_path / "junk.mp4")


class FakeCapture:
    """Delivers ``n`` frames (frame ``bad`` of another size), then reads fail like a dead camera."""

    def __init__(self, n: int, opened: bool = True, bad: int = -1) -> None:
        self.n, self.opened, self.bad, self.count = n, opened, bad, 0
        self.released = threading.Event()
        self.props: dict[int, float] = {}

    def isOpened(self) -> bool:  # noqa: N802
        return self.opened

    def read(self) -> tuple[bool, Any]:
        if self.count >= self.n:  # a dead camera: each read times out empty-handed
            time.sleep(0.05)
            return False, None
        self.count += 1
        time.sleep(0.005)
        shape = (10, 10, 3) if self.count - 1 == self.bad else (48, 64, 3)
        return True, np.full(shape, self.count, np.uint8)

    def get(self, prop: int) -> float:
        return self.props.get(prop, 0.0)

    def set(self, prop: int, value: float) -> bool:
        self.props[prop] = value
        return True

    def release(self) -> None:
        self.released.set()


async def test_camera_delivers_newest_frames_then_stalls() -> None:
    fake = FakeCapture(5, bad=2)
    source = await CameraSource.open("0", stall_timeout_s=0.3, capture_factory=lambda s: fake)
    got = []
    try:
        while True:
            got.append(await source.recv())
            await asyncio.sleep(0.001)
    except SourceStallError as err:
        assert "no frame for 0.3 s" in str(err)
    finally:
        source.close()
    assert 1 <= len(got) <= 4
    assert all(b.t_us > a.t_us and b.index > a.index for a, b in itertools.pairwise(got))
    assert not any(f.lossy for f in got), "a local camera's frames are taken as raw"
    assert source.status.stalls == 1 and source.status.skip_reasons["size"] == 1
    assert source.status.skip_reasons["read_failed"] >= 1
    assert source.status.delivered + source.status.dropped == 4
    assert fake.released.is_set()


async def test_camera_that_cannot_open_or_hangs_is_one_line_error() -> None:
    with pytest.raises(SourceError, match="camera 7: cannot open"):
        await CameraSource.open("7", capture_factory=lambda s: FakeCapture(0, opened=False))

    def hang(spec: str) -> FakeCapture:
        time.sleep(1.0)
        return FakeCapture(0)

    with pytest.raises(SourceError, match=r"did not open within 0\.2 s"):
        await CameraSource.open("rtsp://127.0.0.1:1/x", open_timeout_s=0.2, capture_factory=hang)


async def test_camera_asks_for_the_configured_size() -> None:
    fake = FakeCapture(1)
    source = await CameraSource.open("0", size=(64, 48), capture_factory=lambda s: fake)
    source.close()
    assert fake.props[cv2.CAP_PROP_FRAME_WIDTH] == 64.0


async def test_a_network_camera_s_frames_are_lossy() -> None:
    """A stream over the network reaches the companion through a codec (H.264, MJPEG)."""
    source = await CameraSource.open("rtsp://127.0.0.1:8554/cam",
                                     capture_factory=lambda s: FakeCapture(2))
    try:
        frame = await source.recv()
    finally:
        source.close()
    assert frame.lossy


class RoundingCapture(FakeCapture):
    """A driver that has only 30 and 60 fps modes: asked for another rate, it takes 30."""

    def set(self, prop: int, value: float) -> bool:
        if prop == cv2.CAP_PROP_FPS and value not in (30.0, 60.0):
            value = 30.0
        return super().set(prop, value)


async def test_camera_asks_for_the_configured_rate_and_says_what_it_got(
        caplog: pytest.LogCaptureFixture) -> None:
    fake = FakeCapture(1)
    caplog.set_level("INFO", logger="companion.sources.live")
    source = await CameraSource.open("0", fps=15.0, capture_factory=lambda s: fake)
    source.close()
    assert fake.props[cv2.CAP_PROP_FPS] == 15.0
    assert "camera 0: 15 fps" in caplog.text and "WARNING" not in caplog.text

    caplog.clear()
    source = await CameraSource.open("/dev/video0", fps=15.0,
                                     capture_factory=lambda s: RoundingCapture(1))
    source.close()
    assert "camera /dev/video0: asked for 15 fps, it runs at 30 fps" in caplog.text

    caplog.clear()
    plain = FakeCapture(1)
    source = await CameraSource.open("0", capture_factory=lambda s: plain)
    source.close()
    assert cv2.CAP_PROP_FPS not in plain.props  # no rate configured: the camera's own


class RefusingCapture(FakeCapture):
    """A backend that takes no rate (set returns False) and says it runs at 25 fps."""

    def set(self, prop: int, value: float) -> bool:
        return prop != cv2.CAP_PROP_FPS and super().set(prop, value)

    def get(self, prop: int) -> float:
        return 25.0 if prop == cv2.CAP_PROP_FPS else super().get(prop)


class SilentCapture(FakeCapture):
    """A driver that takes the rate and reports none (CAP_PROP_FPS reads 0)."""

    def get(self, prop: int) -> float:
        return 0.0


async def test_a_camera_that_refuses_or_hides_its_rate_is_said(
        caplog: pytest.LogCaptureFixture) -> None:
    for fake, said in ((RefusingCapture(1), "the driver refused 15 fps (CAP_PROP_FPS); it "
                        "reports 25 fps"),
                       (SilentCapture(1), "asked for 15 fps; it does not say its rate")):
        caplog.clear()
        source = await CameraSource.open("0", fps=15.0, capture_factory=lambda s, f=fake: f)
        source.close()
        assert said in caplog.text, caplog.text


async def test_a_rate_for_a_pipeline_or_a_url_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"framerate=15/1"):
        await CameraSource.open("v4l2src ! videoconvert ! appsink", fps=15.0,
                                capture_factory=lambda s: FakeCapture(1))
    with pytest.raises(ConfigError, match=r"set where it is sent"):
        await CameraSource.open("rtsp://127.0.0.1:8554/cam", fps=15.0,
                                capture_factory=lambda s: FakeCapture(1))


async def test_source_camera_fps_reaches_the_camera(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeCapture(1)
    monkeypatch.setattr(cv2, "VideoCapture", lambda target, backend: fake)
    source = await open_source(SourceConfig(spec="camera:0", camera_fps=15.0))
    source.close()
    assert fake.props[cv2.CAP_PROP_FPS] == 15.0


async def test_real_missing_camera_device_is_a_source_error() -> None:
    with pytest.raises(SourceError, match="cannot open"):
        await CameraSource.open("/dev/video-does-not-exist", open_timeout_s=5.0)


async def test_gstreamer_pipeline_without_gstreamer_support_says_so() -> None:
    if cv2.videoio_registry.hasBackend(cv2.CAP_GSTREAMER):
        pytest.skip("this OpenCV has GStreamer")
    with pytest.raises(SourceError, match="no GSTREAMER support"):
        await CameraSource.open("videotestsrc ! appsink")


def test_camera_targets() -> None:
    assert camera_target("2") == (2, cv2.CAP_ANY)
    assert camera_target("/dev/video1") == ("/dev/video1", cv2.CAP_V4L2)
    assert camera_target("v4l2src ! appsink")[1] == cv2.CAP_GSTREAMER
    assert camera_target("rtsp://10.0.0.2/s")[1] == cv2.CAP_FFMPEG


def test_guessing_the_kind(tmp_path: Path) -> None:
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "stream.toml").write_text("")
    (tmp_path / "o" / "img").mkdir(parents=True)
    assert guess_kind(str(tmp_path / "s")) == "stream"
    assert guess_kind(str(tmp_path / "o")) == "otb"
    assert guess_kind("0") == "camera" and guess_kind("rtsp://h/x") == "camera"
    assert guess_kind("clip.mp4") == "video" and guess_kind("survey") == "sim"
    assert split_spec("rtsp://h/x") == ("auto", "rtsp://h/x")
    assert resolve(SourceConfig(spec="video:weird.bin")).kind == "video"
    with pytest.raises(InputError, match="prefix it with"):
        guess_kind("nothing-like-this")


async def test_open_source_sim_and_otb(tmp_path: Path) -> None:
    (tmp_path / "o" / "img").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "o" / "img" / "0001.jpg"), np.zeros((8, 8, 3), np.uint8))
    otb = await open_source(SourceConfig(spec=str(tmp_path / "o"), realtime=False))
    assert (await otb.recv()).image.shape == (8, 8, 3)
    simulated.register()  # as the command line does at start
    sim = await open_source(SourceConfig(spec="sim:hover", realtime=False))
    assert (await sim.recv()).image.shape == (480, 640, 3)
    with pytest.raises(InputError, match="needs the MAVLink link"):  # no link in the context
        await open_source(SourceConfig(spec="follow:survey", realtime=False))
