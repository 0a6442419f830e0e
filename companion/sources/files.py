"""Sources that replay image files: a recorded stream folder and an OTB sequence folder."""

from __future__ import annotations

import asyncio
import concurrent.futures
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from companion.core.images import ImageProblem, read_image
from companion.core.stream_format import (
    FRAMES_HEADER,
    FrameTruth,
    StreamMeta,
    open_csv,
    read_meta,
)
from companion.core.stream_io import read_truth
from companion.errors import InputError
from companion.sources.base import EndOfStream, Frame, ImageU8, Pacer, SourceStatus

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
LOSSY_SUFFIXES = (".jpg", ".jpeg")


@dataclass(frozen=True)
class Entry:
    """One row of a frame list: recorded index, recorded time and image file.

    ``frame_no`` is set when the frame is number ``frame_no`` (0-based) of a video file.
    """

    index: int
    t_us: int
    path: Path
    frame_no: int | None = None


def lossy(entry: Entry) -> bool:
    """Whether ``entry``'s image was stored by a lossy codec: a JPEG file or a frame of a
    video (an FFV1 video is lossless but counted lossy: the cautious side)."""
    return entry.frame_no is not None or entry.path.suffix.lower() in LOSSY_SUFFIXES


class VideoFrameReader:
    """Reads numbered frames of video files sequentially (reopening to go backwards).

    Used from one thread only (the source's own executor), as OpenCV requires.
    """

    def __init__(self) -> None:
        self._cap: cv2.VideoCapture | None = None
        self._path: Path | None = None
        self._pos = 0

    def read(self, path: Path, frame_no: int) -> ImageU8:
        """Frame ``frame_no`` of ``path`` or :class:`ImageProblem`."""
        if self._cap is None or path != self._path or frame_no < self._pos:
            self.close()
            if not path.is_file():
                raise ImageProblem("missing", f"{path}: video file is missing")
            self._cap, self._path, self._pos = cv2.VideoCapture(str(path)), path, 0
        while self._pos < frame_no and self._cap.grab():
            self._pos += 1
        ok, image = self._cap.read() if self._pos == frame_no else (False, None)
        if not ok or image is None:
            raise ImageProblem("missing", f"{path}: has no frame {frame_no}")
        self._pos += 1
        return np.asarray(image, dtype=np.uint8)

    def close(self) -> None:
        """Release the open video, if any."""
        if self._cap is not None:
            self._cap.release()
        self._cap = None


class FileSequenceSource:
    """Replays a list of image files; bad frames mid-stream are skipped and counted.

    A frame is skipped (``status.skip_reasons``) when its file is missing, truncated or
    corrupt, when its size differs from ``size`` (the first good frame's size when None),
    or when its time does not increase.  With ``loop``, pass k adds ``k * span`` to times
    and ``k * (last index + 1)`` to indices, so both keep increasing.
    """

    def __init__(
        self,
        entries: list[Entry],
        *,
        camera_id: str,
        realtime: bool,
        loop: bool,
        speed: float = 1.0,
        size: tuple[int, int] | None = None,
        frame_period_us: int = 33_333,
    ) -> None:
        if not entries:
            raise InputError("no frames to replay")
        self.entries = entries
        self.camera_id = camera_id
        self.loop = loop
        self.size = size
        self.status = SourceStatus()
        self._pacer = Pacer(realtime, speed)
        self._pos = 0
        self._pass = 0
        self._delivered_this_pass = 0
        self._last_t_us: int | None = None
        self._span_us = entries[-1].t_us - entries[0].t_us + frame_period_us
        self._index_step = max(e.index for e in entries) + 1
        self._closed = False
        self._video = VideoFrameReader()
        self._video_pool: concurrent.futures.ThreadPoolExecutor | None = None

    async def recv(self) -> Frame:
        """The next readable frame, paced; :class:`EndOfStream` at the end."""
        loop = asyncio.get_running_loop()
        while True:
            entry = self._next_entry()
            t_us = entry.t_us + self._pass * self._span_us
            if self._last_t_us is not None and t_us <= self._last_t_us:
                self.status.skip("time_backwards", f"{entry.path}: time {t_us} us not increasing")
                continue
            try:
                image = await self._load(loop, entry)
            except ImageProblem as err:
                self.status.skip(err.reason, str(err))
                continue
            if not self._size_ok(image, entry.path):
                continue
            await self._pacer.wait(t_us)
            self._last_t_us = t_us
            self._delivered_this_pass += 1
            self.status.delivered += 1
            index = entry.index + self._pass * self._index_step
            return Frame(index, t_us, image, self.camera_id, lossy=lossy(entry))

    async def _load(self, loop: asyncio.AbstractEventLoop, entry: Entry) -> ImageU8:
        if entry.frame_no is None:
            return await loop.run_in_executor(None, read_image, entry.path)
        if self._video_pool is None:
            self._video_pool = concurrent.futures.ThreadPoolExecutor(1, "stream-video")
        return await loop.run_in_executor(
            self._video_pool, self._video.read, entry.path, entry.frame_no
        )

    def _next_entry(self) -> Entry:
        if self._closed:
            raise EndOfStream("source closed")
        if self._pos >= len(self.entries):
            if not self.loop:
                raise EndOfStream("end of recording")
            if self._delivered_this_pass == 0:
                raise InputError(f"no readable frame in a whole pass ({self.status.last_error})")
            self._pos = 0
            self._pass += 1
            self._delivered_this_pass = 0
            self.status.loops += 1
        entry = self.entries[self._pos]
        self._pos += 1
        return entry

    def _size_ok(self, image: ImageU8, path: Path) -> bool:
        size = (int(image.shape[1]), int(image.shape[0]))
        if self.size is None:
            self.size = size
        if size != self.size:
            self.status.skip("size", f"{path}: size {size} differs from {self.size}")
            return False
        return True

    def close(self) -> None:
        """Stop delivering and release a video file being read."""
        self._closed = True
        if self._video_pool is not None:
            self._video_pool.submit(self._video.close)
            self._video_pool.shutdown(wait=False)


class RecordedStreamSource(FileSequenceSource):
    """A recorded stream folder (docs/formats.md); frames keep their recorded times."""

    def __init__(
        self, folder: Path, *, realtime: bool = True, loop: bool = False, speed: float = 1.0
    ) -> None:
        self.folder = Path(folder)
        self.meta: StreamMeta = read_meta(self.folder)
        status_skips, entries = read_frame_list(self.folder)
        period = round(1e6 / self.meta.fps) if self.meta.fps > 0 else 33_333
        super().__init__(
            entries,
            camera_id=self.meta.camera_id,
            realtime=realtime,
            loop=loop,
            speed=speed,
            size=(self.meta.camera.width, self.meta.camera.height),
            frame_period_us=period,
        )
        for detail in status_skips:
            self.status.skip("bad_row", detail)
        self._truth: dict[int, FrameTruth] | None = None

    def truth(self, index: int) -> FrameTruth | None:
        """The recorded truth of frame ``index`` (None when the stream has none for it).

        Truth files are read on the first call.  In a looped replay, ``index`` is the
        delivered index: it is mapped back to the recorded one.
        """
        if self._truth is None:
            self._truth = read_truth(self.folder)
        return self._truth.get(index % self._index_step if self.loop else index)


def read_frame_list(folder: Path) -> tuple[list[str], list[Entry]]:
    """Parse ``frames.csv``: (problems with malformed rows, entries)."""
    path = folder / "frames.csv"
    fh, _, reader = open_csv(path, FRAMES_HEADER)
    problems: list[str] = []
    entries: list[Entry] = []
    with fh:
        for n, row in enumerate(reader, start=2):
            if not row:
                continue
            try:
                name, _, number = row[2].strip().partition("#")
                frame_no = int(number) if number else None
                entries.append(Entry(int(row[0]), int(row[1]), folder / name, frame_no))
            except (ValueError, IndexError):
                problems.append(f"{path}:{n}: malformed row {row}")
    if not entries:
        raise InputError(f"{path}: lists no frames")
    return problems, entries


class OtbSource(FileSequenceSource):
    """An OTB sequence folder (``img/*.jpg``, ``groundtruth_rect.txt``), timed at ``fps``."""

    def __init__(
        self,
        folder: Path,
        *,
        fps: float = 30.0,
        realtime: bool = False,
        loop: bool = False,
        speed: float = 1.0,
        camera_id: str = "otb",
    ) -> None:
        self.folder = Path(folder)
        img = self.folder / "img"
        if not img.is_dir():
            raise InputError(f"{self.folder}: not an OTB sequence folder (no img/)")
        files = sorted(p for p in img.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise InputError(f"{img}: holds no images")
        period = 1e6 / fps
        entries = [Entry(i, round(i * period), p) for i, p in enumerate(files)]
        super().__init__(
            entries,
            camera_id=camera_id,
            realtime=realtime,
            loop=loop,
            speed=speed,
            frame_period_us=round(period),
        )


def read_otb_groundtruth(folder: Path) -> np.ndarray:
    """``groundtruth_rect.txt`` as an Nx4 float array of x, y, w, h, **0-based** pixels.

    OTB files are 1-based and separate values by commas, tabs or spaces; this subtracts 1
    from x and y so that boxes match the rest of the project (and ``truth_boxes.csv``).
    """
    path = Path(folder) / "groundtruth_rect.txt"
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: missing") from None
    rows = []
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        parts = [p for p in re.split(r"[,\s]+", line.strip()) if p]
        try:
            x, y, w, h = (float(p) for p in parts[:4])
        except ValueError:
            raise InputError(f"{path}:{n}: expected x,y,w,h numbers, got {line!r}") from None
        rows.append((x - 1.0, y - 1.0, w, h))
    return np.asarray(rows, dtype=np.float64).reshape(-1, 4)
