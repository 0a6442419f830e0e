"""Video files and live cameras through OpenCV, kept off the event loop.

A ``cv2.VideoCapture`` is used from one thread only: a video file reads in its own
single-thread executor; a live camera reads in a capture thread that hands only the newest
frame to the event loop (``loop.call_soon_threadsafe``), so a slow consumer sees fresh
frames, never a backlog.  A camera that delivers nothing for ``stall_timeout_s`` makes
``recv`` raise :class:`SourceStallError` (and count a stall); the capture thread keeps
trying, so a later ``recv`` resumes when the camera comes back.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from companion.errors import ConfigError, InputError, SourceError
from companion.sources.base import EndOfStream, Frame, ImageU8, Pacer, SourceStatus, monotonic_us
from companion.sources.config import camera_rate_refusal

log = logging.getLogger(__name__)

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mjpeg", ".mjpg")


class SourceStallError(SourceError):
    """A live source delivered no frame within its stall timeout."""


class Capture(Protocol):
    """The part of ``cv2.VideoCapture`` the sources use (tests pass fakes)."""

    def isOpened(self) -> bool: ...  # noqa: N802 (OpenCV's name)
    def read(self) -> tuple[bool, Any]: ...
    def get(self, prop: int) -> float: ...
    def set(self, prop: int, value: float) -> bool: ...
    def release(self) -> None: ...


CaptureFactory = Callable[[str], Capture]


def _size(image: ImageU8) -> tuple[int, int]:
    return int(image.shape[1]), int(image.shape[0])


class VideoFileSource:
    """A video file; frame times from the container (else ``fps``), paced or fast, loopable."""

    def __init__(
        self,
        path: Path,
        *,
        realtime: bool = True,
        loop: bool = False,
        speed: float = 1.0,
        fps: float = 30.0,
        camera_id: str = "video",
    ) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: video file does not exist")
        self.cap = cv2.VideoCapture(str(self.path))
        if not self.cap.isOpened():
            raise InputError(f"{self.path}: OpenCV cannot open this video")
        file_fps = float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = file_fps if 0.0 < file_fps < 1000.0 else fps
        self.loop, self.camera_id = loop, camera_id
        self.status = SourceStatus()
        self._pacer = Pacer(realtime, speed)
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="video")
        self._n = 0  # frames read in this pass
        self._pass_offset = (0, 0)  # (index, t_us) added in later passes
        self._size: tuple[int, int] | None = None
        self._last_t_us: int | None = None

    def _read(self) -> ImageU8 | None:
        ok, image = self.cap.read()
        return np.asarray(image, dtype=np.uint8) if ok and image is not None else None

    async def recv(self) -> Frame:
        """The next frame of the file; EndOfStream at its end (unless looping)."""
        loop = asyncio.get_running_loop()
        while True:
            image = await loop.run_in_executor(self._pool, self._read)
            if image is None:
                await self._end_of_pass(loop)
                continue
            index = self._pass_offset[0] + self._n
            t_us = self._pass_offset[1] + round(self._n * 1e6 / self.fps)
            self._n += 1
            if self._size is None:
                self._size = _size(image)
            if _size(image) != self._size:
                self.status.skip("size", f"{self.path}: frame {index} size {_size(image)}")
                continue
            await self._pacer.wait(t_us)
            self._last_t_us = t_us
            self.status.delivered += 1
            return Frame(index, t_us, image, self.camera_id, lossy=True)

    async def _end_of_pass(self, loop: asyncio.AbstractEventLoop) -> None:
        if not self.loop or self._n == 0:
            raise EndOfStream(f"{self.path}: end of video")
        self._pass_offset = (self._pass_offset[0] + self._n,
                             self._pass_offset[1] + round(self._n * 1e6 / self.fps))
        self._n = 0
        self.status.loops += 1
        await loop.run_in_executor(self._pool, self.cap.set, cv2.CAP_PROP_POS_FRAMES, 0.0)

    def close(self) -> None:
        """Release the file and the reader thread."""
        self._pool.submit(self.cap.release)
        self._pool.shutdown(wait=False)


def camera_target(spec: str) -> tuple[int | str, int]:
    """OpenCV's (target, backend) for a camera spec: index, V4L2 path, GStreamer, URL."""
    s = spec.strip()
    if s.isdigit():
        return int(s), cv2.CAP_ANY
    if s.startswith("/dev/"):
        return s, cv2.CAP_V4L2
    if "!" in s:
        return s, cv2.CAP_GSTREAMER
    return s, cv2.CAP_FFMPEG


def _has_backend(backend: int) -> bool:
    return backend == cv2.CAP_ANY or bool(cv2.videoio_registry.hasBackend(backend))


def open_capture(spec: str) -> Capture:
    """``cv2.VideoCapture`` for a camera spec (see :func:`camera_target`)."""
    target, backend = camera_target(spec)
    return cv2.VideoCapture(target, backend)


def ask_rate(cap: Capture, spec: str, fps: float) -> None:
    """Ask the camera for ``fps`` frames a second and log what it says it will deliver (a
    driver may round to a rate it has, or keep its own: the log says so, the companion runs
    on; the frames' own times are what the pipeline uses)."""
    taken = bool(cap.set(cv2.CAP_PROP_FPS, float(fps)))
    got = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    says = f"it reports {got:g} fps" if got > 0.0 else "it does not say its rate"
    if not taken:
        log.warning("camera %s: the driver refused %g fps (CAP_PROP_FPS); %s", spec, fps, says)
    elif got <= 0.0:
        log.warning("camera %s: asked for %g fps; %s", spec, fps, says)
    elif abs(got - fps) > 0.05 * fps:
        log.warning("camera %s: asked for %g fps, it runs at %g fps (the rates its modes "
                    "have, whole numbers on V4L2: v4l2-ctl --list-formats-ext)", spec, fps, got)
    else:
        log.info("camera %s: %g fps", spec, got)


class CameraSource:
    """A live camera; frames stamped with the monotonic clock as they arrive.

    Use :meth:`open` (it opens the device off the event loop within ``open_timeout_s``).
    """

    def __init__(
        self,
        spec: str,
        *,
        camera_id: str = "cam0",
        stall_timeout_s: float = 2.0,
        size: tuple[int, int] | None = None,
        fps: float | None = None,
        capture_factory: CaptureFactory = open_capture,
    ) -> None:
        self.spec, self.camera_id = spec, camera_id
        self.stall_timeout_s = stall_timeout_s
        self.size = size
        self.fps = fps  # asked of the camera (None: its own rate)
        self.status = SourceStatus()
        self._factory = capture_factory
        self._cap: Capture | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._latest: Frame | None = None
        self._ready: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._index = 0

    @classmethod
    async def open(cls, spec: str, *, open_timeout_s: float = 5.0, **kwargs: Any) -> CameraSource:
        """Open the camera and start its capture thread, or raise :class:`SourceError`."""
        source = cls(spec, **kwargs)
        backend = camera_target(spec)[1]
        refusal = None if source.fps is None else camera_rate_refusal(spec, source.fps)
        if refusal is not None:
            raise ConfigError(f"source.camera_fps: camera {spec}: {refusal}")
        if source._factory is open_capture and not _has_backend(backend):
            name = cv2.videoio_registry.getBackendName(backend)
            raise SourceError(f"camera {spec}: this OpenCV build has no {name} support")
        loop = asyncio.get_running_loop()
        pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="camera-open")
        try:
            cap = await asyncio.wait_for(
                loop.run_in_executor(pool, source._factory, spec), open_timeout_s
            )
        except TimeoutError:
            raise SourceError(f"camera {spec}: did not open within {open_timeout_s:g} s") from None
        finally:
            pool.shutdown(wait=False)
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"camera {spec}: cannot open (no such device, busy, or no access)")
        if source.size is not None:  # ask for the configured size; other sizes are skipped
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(source.size[0]))
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(source.size[1]))
        if source.fps is not None:
            ask_rate(cap, spec, source.fps)
        source._start(cap, loop)
        return source

    def _start(self, cap: Capture, loop: asyncio.AbstractEventLoop) -> None:
        self._cap, self._loop = cap, loop
        self._ready = asyncio.Event()
        self._thread = threading.Thread(target=self._run, name="camera-capture", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        """Capture thread: read, stamp, hand the newest frame to the loop."""
        assert self._cap is not None and self._loop is not None
        failures = 0
        while not self._stop.is_set():
            ok, image = self._cap.read()
            t_us = monotonic_us()
            try:
                if ok and image is not None:
                    failures = 0
                    frame = np.asarray(image, np.uint8)
                    self._loop.call_soon_threadsafe(self._deliver, frame, t_us)
                    continue
                failures += 1
                self._loop.call_soon_threadsafe(
                    self.status.skip, "read_failed", f"camera {self.spec}: read failed"
                )
            except RuntimeError:  # the loop is closed: nobody is listening any more
                return
            time.sleep(min(0.5, 0.01 * failures))

    def _deliver(self, image: ImageU8, t_us: int) -> None:
        if self.size is None:
            self.size = _size(image)
        if _size(image) != self.size:
            self.status.skip("size", f"camera {self.spec}: frame size {_size(image)}")
            return
        if self._latest is not None:
            self.status.dropped += 1  # a newer frame replaced it before recv took it
        self._latest = Frame(self._index, t_us, image, self.camera_id,
                             lossy="://" in self.spec)
        self._index += 1
        assert self._ready is not None
        self._ready.set()

    async def recv(self) -> Frame:
        """The newest frame; :class:`SourceStallError` after ``stall_timeout_s`` without one."""
        if self._ready is None or self._stop.is_set():
            raise EndOfStream(f"camera {self.spec}: closed")
        try:
            await asyncio.wait_for(self._ready.wait(), self.stall_timeout_s)
        except TimeoutError:
            self.status.stalls += 1
            self.status.last_error = f"camera {self.spec}: no frame for {self.stall_timeout_s:g} s"
            raise SourceStallError(self.status.last_error) from None
        self._ready.clear()
        frame, self._latest = self._latest, None
        assert frame is not None
        self.status.delivered += 1
        return frame

    def close(self) -> None:
        """Stop the capture thread and release the device."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            if self._thread.is_alive():  # stuck in a driver read: releasing now could crash
                log.warning("camera %s: capture thread still blocked; not releasing", self.spec)
                return
        if self._cap is not None:
            self._cap.release()
