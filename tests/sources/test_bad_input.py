"""Bad input: one-line errors when opening, skipped-and-counted frames mid-stream."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from companion.core.images import write_image
from companion.core.stream_format import StreamMeta
from companion.core.stream_io import StreamWriter
from companion.errors import InputError
from companion.sources.base import EndOfStream, Frame
from companion.sources.files import OtbSource, RecordedStreamSource, read_otb_groundtruth
from tracker.camera import CameraModel

CAM = CameraModel(width=32, height=24, fx=30.0, fy=30.0, cx=15.5, cy=11.5)


def make_stream(folder: Path, n: int = 5) -> None:
    with StreamWriter(folder, StreamMeta(fps=10.0, camera=CAM)) as writer:
        for i in range(n):
            writer.write(Frame(i, i * 100_000, np.full((24, 32, 3), 10 * i, np.uint8)))


async def drain(source: RecordedStreamSource | OtbSource) -> list[int]:
    out = []
    while True:
        try:
            out.append((await source.recv()).index)
        except EndOfStream:
            return out


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda d: None, "does not exist"),
        (lambda d: d.mkdir(), "stream.toml: missing"),
        (lambda d: (d.mkdir(), (d / "stream.toml").write_text("fps = [")), "not valid TOML"),
        (lambda d: (d.mkdir(), (d / "stream.toml").write_text('format = "x"')), "format must"),
    ],
)
def test_opening_a_bad_folder_is_one_line_error(tmp_path: Path, setup, message: str) -> None:
    setup(tmp_path / "s")
    with pytest.raises(InputError, match=message) as info:
        RecordedStreamSource(tmp_path / "s")
    assert "\n" not in str(info.value)


def test_missing_frames_csv_or_bad_header(tmp_path: Path) -> None:
    make_stream(tmp_path / "s")
    csv = tmp_path / "s" / "frames.csv"
    csv.write_text("idx,time,file\n0,0,frames/000000.png\n")
    with pytest.raises(InputError, match="header must start with index,t_us,file"):
        RecordedStreamSource(tmp_path / "s")
    csv.unlink()
    with pytest.raises(InputError, match=r"frames\.csv: missing"):
        RecordedStreamSource(tmp_path / "s")


async def test_bad_frames_are_skipped_and_counted(tmp_path: Path) -> None:
    make_stream(tmp_path / "s", n=7)
    frames = tmp_path / "s" / "frames"
    (frames / "000001.png").unlink()  # missing
    data = (frames / "000002.png").read_bytes()
    (frames / "000002.png").write_bytes(data[: len(data) // 2])  # truncated
    (frames / "000003.png").write_bytes(b"\x89PNG garbage" + data[-12:])  # corrupt
    write_image(frames / "000004.png", np.zeros((10, 10, 3), np.uint8))  # other size
    csv = tmp_path / "s" / "frames.csv"
    lines = csv.read_text().splitlines()
    lines[7] = "6,400000,frames/000006.png"  # time going backwards
    csv.write_text("\n".join([*lines, "oops,row"]) + "\n")
    source = RecordedStreamSource(tmp_path / "s", realtime=False)
    assert await drain(source) == [0, 5]
    assert source.status.skip_reasons == {
        "bad_row": 1, "missing": 1, "truncated": 1, "corrupt": 1, "size": 1, "time_backwards": 1,
    }
    assert source.status.skipped == 6 and source.status.delivered == 2


async def test_loop_over_unreadable_stream_ends_instead_of_hanging(tmp_path: Path) -> None:
    make_stream(tmp_path / "s", n=2)
    for p in (tmp_path / "s" / "frames").iterdir():
        p.write_bytes(b"nope")
    source = RecordedStreamSource(tmp_path / "s", realtime=False, loop=True)
    with pytest.raises(InputError, match="no readable frame"):
        await source.recv()


async def test_otb_folder(tmp_path: Path) -> None:
    (tmp_path / "seq" / "img").mkdir(parents=True)
    for i in range(3):
        write_image(tmp_path / "seq" / "img" / f"{i + 1:04d}.jpg",
                    np.full((24, 32, 3), 50 * i, np.uint8))
    (tmp_path / "seq" / "groundtruth_rect.txt").write_text("1,2,3,4\n5\t6\t7\t8\n9 10 11 12\n")
    source = OtbSource(tmp_path / "seq", fps=20.0)
    frames = [await source.recv() for _ in range(3)]
    assert [f.t_us for f in frames] == [0, 50_000, 100_000]
    assert abs(int(frames[2].image.mean()) - 100) <= 2
    gt = read_otb_groundtruth(tmp_path / "seq")
    assert gt.tolist() == [[0, 1, 3, 4], [4, 5, 7, 8], [8, 9, 11, 12]]
    with pytest.raises(InputError, match="no img/"):
        OtbSource(tmp_path)


def test_real_otb_sequence_if_present() -> None:
    root = Path(__file__).resolve().parents[2]
    shared = Path(os.environ.get("LMC_SHARED_DATA", root / ".." / "shared" / "data"))
    data = shared / "otb" / "Coke"
    if not data.is_dir():
        pytest.skip(f"shared OTB data absent at {data}")
    gt = read_otb_groundtruth(data)
    assert gt.shape == (291, 4) and gt[0].tolist() == [297, 159, 48, 80]


def test_truncated_jpeg_and_png_are_detected(tmp_path: Path) -> None:
    from companion.core.images import ImageProblem, read_image

    img = np.random.default_rng(0).integers(0, 256, (24, 32, 3), dtype=np.uint8)
    for suffix in (".jpg", ".png"):
        path = tmp_path / f"a{suffix}"
        write_image(path, img)
        assert read_image(path).shape == (24, 32, 3)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) - 40])
        with pytest.raises(ImageProblem, match="truncated") as info:
            read_image(path)
        assert info.value.reason == "truncated"
