"""Why no fix can come, named: the diagnosis behind the pipeline's ``blocked`` state.

:class:`NoFixWatch` is called by :class:`companion.app.CompanionApp` on every health
update; it returns a :class:`~companion.pipeline.health.Blocker` or None.  The state
machine uses it only while no fix is fresh, so a diagnosis never hides a working flight.
Causes, first match wins (docs/monitoring.md has the table):

* a static one found before the first frame (:func:`companion.flightmap.static_blocker`:
  ``origin-far``, ``no-landmarks``, ``no-references``);
* ``link-never-up``: no HEARTBEAT from the autopilot since the start, for ``link_wait_s``;
* ``no-attitude``: the link is up but no ATTITUDE came for ``attitude_wait_s``;
* ``none-in-view``: from the autopilot's own position and attitude, no landmark of the
  map falls in the camera's image.

The dynamic causes wait ``grace_s`` after the start (a link and its streams take a
moment to come up) and are recomputed at most every ``period_s``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from companion.pipeline.health import Blocker
from tracker.boxes import in_view_share
from tracker.camera import CameraModel
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import AttitudeSample, MapLandmark


class AttitudeSource(Protocol):
    """Where a frame's attitude comes from (the autopilot's ATTITUDE, or a recording's
    truth): the attitude at a time, and when the newest sample arrived."""

    def at(self, t_us: int, max_gap_us: int = 100_000) -> AttitudeSample | None: ...
    def last_us(self) -> int | None: ...


class Link(Protocol):
    """What the watch needs of the bridge."""

    @property
    def link_up(self) -> bool: ...
    def latest(self, name: str) -> Any: ...


@dataclass(frozen=True)
class WatchTimes:
    """How long each dynamic cause waits before it is named (seconds)."""

    grace_s: float = 3.0
    link_wait_s: float = 3.0
    attitude_wait_s: float = 2.0
    period_s: float = 0.5


def landmarks_in_view(camera: CameraModel, landmarks: Sequence[MapLandmark],
                      position_ned_m: Sequence[float], attitude_rpy_rad: tuple[float, float, float]
                      ) -> list[str]:
    """Ids of the landmarks whose face falls (partly) inside the image from this pose."""
    seen = []
    for lm in landmarks:
        cam = camera.world_to_camera(landmark_corners_ned(lm), np.asarray(position_ned_m),
                                     attitude_rpy_rad)
        if np.any(cam[:, 2] <= 0.1):
            continue
        if in_view_share(camera.project_camera_points(cam), camera.width, camera.height) > 0:
            seen.append(lm.landmark_id)
    return seen


class NoFixWatch:
    """The diagnosis (module docstring); call it for the current :class:`Blocker`."""

    def __init__(self, static: Blocker | None, link: Link, attitude: AttitudeSource,
                 camera: CameraModel, landmarks: Sequence[MapLandmark], endpoint: str,
                 times: WatchTimes | None = None,
                 clock_s: Callable[[], float] = time.monotonic) -> None:
        self.static = static
        self.link = link
        self.attitude = attitude
        self.camera = camera
        self.landmarks = list(landmarks)
        self.endpoint = endpoint
        self.times = times or WatchTimes()
        self.clock_s = clock_s
        self._t0 = clock_s()
        self._ever_up = False
        self._next_s = -math.inf
        self._last: Blocker | None = static

    def __call__(self) -> Blocker | None:
        if self.static is not None:
            return self.static
        now = self.clock_s()
        self._ever_up = self._ever_up or self.link.link_up
        if now < self._next_s:
            return self._last
        self._next_s = now + self.times.period_s
        self._last = self._dynamic(now)
        return self._last

    def _dynamic(self, now: float) -> Blocker | None:
        waited = now - self._t0
        if not self._ever_up:
            if waited < self.times.link_wait_s:
                return None
            return Blocker("link-never-up", f"no HEARTBEAT from the autopilot on "
                           f"{self.endpoint} in {waited:.0f} s (mavlink.endpoint)")
        if waited < self.times.grace_s or not self.link.link_up:
            return None  # a link that went down is the state ``link-down``
        last = self.attitude.last_us()
        age_s = math.inf if last is None else now - last / 1e6
        if age_s > self.times.attitude_wait_s:
            since = "ever" if last is None else f"{age_s:.0f} s"
            return Blocker("no-attitude", f"no ATTITUDE from the autopilot for {since}: the "
                           "pose needs the vehicle's attitude")
        return self._in_view()

    def _in_view(self) -> Blocker | None:
        item = self.link.latest("LOCAL_POSITION_NED")
        last = self.attitude.last_us()
        sample = None if last is None else self.attitude.at(last)
        if item is None or sample is None or not self.landmarks:
            return None
        v = item.value
        pos = (float(v.north_m), float(v.east_m), float(v.down_m))
        rpy = (sample.roll_rad, sample.pitch_rad, sample.yaw_rad)
        if landmarks_in_view(self.camera, self.landmarks, pos, rpy):
            return None
        near = min(self.landmarks, key=lambda lm: math.dist(lm.position_ned_m, pos))
        return Blocker("none-in-view", "no landmark of the map is in the camera's view from "
                       f"the autopilot's position N {pos[0]:.1f} E {pos[1]:.1f} D "
                       f"{pos[2]:.1f} m (nearest {near.landmark_id!r}, "
                       f"{math.dist(near.position_ned_m, pos):.0f} m away)")
