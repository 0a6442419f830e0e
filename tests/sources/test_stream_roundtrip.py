"""Recorded stream folders: write -> read round trip and the format's rules."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from companion.core.stream_format import (
    FrameTruth,
    Origin,
    StreamMeta,
    TruthBox,
    TruthCamera,
    TruthPose,
    read_meta,
)
from companion.core.stream_io import (
    StreamWriter,
    read_telemetry,
    read_truth_boxes,
    read_truth_camera,
    read_truth_pose,
    read_truth_range,
)
from companion.errors import InputError
from companion.sources.base import EndOfStream, Frame
from companion.sources.files import RecordedStreamSource
from tracker.camera import CameraModel

CAM = CameraModel(width=64, height=48, fx=60.0, fy=61.0, cx=31.5, cy=23.5,
                  distortion=(0.1, -0.01, 0.0, 0.0, 0.0), mount_rpy_deg=(0.0, -30.0, 0.0))


def make_frames(n: int, seed: int = 0) -> list[Frame]:
    rng = np.random.default_rng(seed)
    return [
        Frame(i, 1_000_000 + i * 33_333, rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), "c1")
        for i in range(n)
    ]


def write_stream(folder: Path, frames: list[Frame], fmt: str = "png") -> None:
    meta = StreamMeta(fps=30.0, camera=CAM, camera_id="c1",
                      origin=Origin(47.0, 8.0, 400.0), provenance={"by": "test"})
    with StreamWriter(folder, meta, image_format=fmt) as writer:
        for f in frames:
            corners = np.array([[1.0, 2.0], [11.5, 2.0], [11.5, 9.25], [1.0, 9.25]])
            truth = FrameTruth(
                boxes=(TruthBox("sign-1", 1.0, 2.0, 10.5, 7.25, corners, 0.75, 0.5),
                       TruthBox("wall-2", 3.0, 4.0, 5.0, 6.0)),
                pose=TruthPose(1.5, -2.25, -10.0, 0.01, -0.02, 1.5),
                camera=TruthCamera((1.5, -2.25, -10.0), np.eye(3)),
                range_m=None if f.index == 1 else 10.125,
            )
            writer.write(f, truth)


async def read_all(source: RecordedStreamSource) -> list[Frame]:
    out = []
    while True:
        try:
            out.append(await source.recv())
        except EndOfStream:
            return out


async def test_png_round_trip_is_bit_exact(tmp_path: Path) -> None:
    frames = make_frames(5)
    write_stream(tmp_path / "s", frames)
    source = RecordedStreamSource(tmp_path / "s", realtime=False)
    got = await read_all(source)
    assert [f.index for f in got] == [f.index for f in frames]
    assert [f.t_us for f in got] == [f.t_us for f in frames]
    for a, b in zip(got, frames, strict=True):
        assert a.camera_id == "c1" and not a.lossy
        assert np.array_equal(a.image, b.image)
    assert source.status.delivered == 5 and source.status.skipped == 0


async def test_ffv1_video_stream_round_trip_is_bit_exact(tmp_path: Path) -> None:
    frames = make_frames(4, seed=2)
    write_stream(tmp_path / "s", frames, fmt="ffv1")
    assert (tmp_path / "s" / "frames.csv").read_text().splitlines()[2].endswith("frames.mkv#1")
    source = RecordedStreamSource(tmp_path / "s", realtime=False, loop=True)
    got = [await source.recv() for _ in range(6)]  # the loop reopens the video
    source.close()
    for a, b in zip(got, [*frames, *frames[:2]], strict=True):
        assert np.array_equal(a.image, b.image)
        assert a.lossy, "a video's frames count as lossy, FFV1 too (the cautious side)"
    assert got[5].index == 5


async def test_missing_video_frames_are_skipped(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(2), fmt="ffv1")
    csv = tmp_path / "s" / "frames.csv"
    csv.write_text(csv.read_text() + "2,2000000,frames.mkv#9\n3,3000000,gone.mkv#0\n")
    source = RecordedStreamSource(tmp_path / "s", realtime=False)
    assert len(await read_all(source)) == 2
    assert source.status.skip_reasons == {"missing": 2}


async def test_jpeg_round_trip_is_close(tmp_path: Path) -> None:
    frames = [Frame(i, i * 10, np.full((48, 64, 3), 40 * i, np.uint8)) for i in range(3)]
    write_stream(tmp_path / "s", frames, fmt="jpg")
    got = await read_all(RecordedStreamSource(tmp_path / "s", realtime=False))
    for a, b in zip(got, frames, strict=True):
        assert np.abs(a.image.astype(int) - b.image.astype(int)).max() <= 2
        assert a.lossy


def test_meta_and_truth_round_trip(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(3))
    meta = read_meta(tmp_path / "s")
    assert meta.camera == CAM and meta.fps == 30.0 and meta.camera_id == "c1"
    assert meta.origin == Origin(47.0, 8.0, 400.0)
    assert meta.provenance["by"] == "test" and meta.provenance["image_format"] == "png"
    boxes = read_truth_boxes(tmp_path / "s")
    assert sorted(boxes) == [0, 1, 2]
    box = boxes[2][0]
    assert (box.landmark_id, box.x, box.y, box.w, box.h) == ("sign-1", 1.0, 2.0, 10.5, 7.25)
    assert box.corners_px is not None and box.corners_px[2].tolist() == [11.5, 9.25]
    assert box.in_view_frac == 0.75 and box.occluded_frac == 0.5
    plain = boxes[2][1]
    assert plain.corners_px is None and (plain.x, plain.w, plain.in_view_frac) == (3.0, 5.0, 1.0)
    t_us, pose = read_truth_pose(tmp_path / "s")[1]
    assert t_us == 1_033_333 and pose == TruthPose(1.5, -2.25, -10.0, 0.01, -0.02, 1.5)
    assert np.array_equal(read_truth_camera(tmp_path / "s")[0].r_ned_cam, np.eye(3))
    assert read_truth_range(tmp_path / "s") == {0: 10.125, 1: None, 2: 10.125}
    source = RecordedStreamSource(tmp_path / "s", realtime=False, loop=True)
    truth = source.truth(4)  # second pass: recorded frame 1
    assert truth is not None and truth.range_m is None and truth.pose is not None
    assert truth.boxes[0].landmark_id == "sign-1"
    assert RecordedStreamSource(tmp_path / "s", realtime=False).truth(99) is None


def test_csv_headers_are_exactly_the_documented_ones(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(1))
    first = {n: (tmp_path / "s" / n).read_text().splitlines()[0] for n in
             ("frames.csv", "truth_boxes.csv", "truth_pose.csv")}
    assert first["frames.csv"] == "index,t_us,file"
    assert first["truth_boxes.csv"].startswith("index,landmark_id,x,y,w,h,")
    assert first["truth_pose.csv"] == (
        "index,t_us,north_m,east_m,down_m,roll_rad,pitch_rad,yaw_rad")


def test_writer_refuses_existing_stream_and_bad_frames(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(1))
    with pytest.raises(InputError, match="already holds a stream"):
        write_stream(tmp_path / "s", make_frames(1))
    meta = StreamMeta(fps=30.0, camera=CAM)
    with StreamWriter(tmp_path / "t", meta) as writer:
        writer.write(make_frames(1)[0])
        with pytest.raises(InputError, match="does not increase"):
            writer.write(make_frames(1)[0])
        with pytest.raises(InputError, match="size"):
            writer.write(Frame(5, 10**9, np.zeros((10, 10, 3), np.uint8)))


def test_reader_ignores_unknown_keys_and_refuses_newer_major(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(1))
    toml = tmp_path / "s" / "stream.toml"
    text = toml.read_text()
    toml.write_text("future_key = 3\n" + text + "\n[future_table]\nx = 1\n")
    assert read_meta(tmp_path / "s").fps == 30.0
    toml.write_text(text.replace("version = 2", "version = 3"))
    with pytest.raises(InputError, match="newer than this program"):
        read_meta(tmp_path / "s")


def test_version_1_streams_still_read_and_telemetry_round_trips(tmp_path: Path) -> None:
    """Format version 2 adds ``telemetry.csv``; a version-1 folder (no telemetry) reads."""
    write_stream(tmp_path / "v1", make_frames(2))
    toml = tmp_path / "v1" / "stream.toml"
    toml.write_text(toml.read_text().replace("version = 2", "version = 1"))
    assert read_meta(tmp_path / "v1").version == 1
    assert read_telemetry(tmp_path / "v1") == []
    with StreamWriter(tmp_path / "v2", StreamMeta(fps=30.0, camera=CAM)) as writer:
        writer.write(make_frames(1)[0])
        writer.write_telemetry(12, "ATTITUDE", {"roll": 0.1, "pitch": -0.2, "yaw": 3.0})
    assert read_meta(tmp_path / "v2").version == 2
    assert read_telemetry(tmp_path / "v2") == [
        (12, "ATTITUDE", {"roll": 0.1, "pitch": -0.2, "yaw": 3.0})]


async def test_loop_keeps_index_and_time_increasing(tmp_path: Path) -> None:
    write_stream(tmp_path / "s", make_frames(3))
    source = RecordedStreamSource(tmp_path / "s", realtime=False, loop=True)
    got = [await source.recv() for _ in range(7)]
    assert [f.index for f in got] == [0, 1, 2, 3, 4, 5, 6]
    assert all(b.t_us > a.t_us for a, b in itertools.pairwise(got))
    assert np.array_equal(got[3].image, got[0].image)
    assert source.status.loops == 2


async def test_realtime_replay_keeps_recorded_spacing(tmp_path: Path) -> None:
    frames = [Frame(i, i * 40_000, np.zeros((48, 64, 3), np.uint8)) for i in range(4)]
    write_stream(tmp_path / "s", frames)
    source = RecordedStreamSource(tmp_path / "s", realtime=True, speed=4.0)
    import time

    start = time.monotonic()
    await read_all(source)
    # 3 gaps of 40 ms at 4x speed = 30 ms at least; this is a lower bound, not a speed claim.
    assert time.monotonic() - start >= 0.029
