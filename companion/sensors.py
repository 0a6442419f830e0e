"""The autopilot's side sensors, looked up at a frame's capture time for the pose solver.

:class:`SensorHistory` follows three of the bridge's telemetry streams and answers, for a
frame's capture time, the :class:`~companion.side_sensors.SideSensors` the solver uses:

* ``ATTITUDE``: the autopilot's attitude, interpolated between the two nearest samples (yaw
  the short way round), with the configured 1-sigma (``pose.attitude_*_sigma_deg``).
  ArduPilot reports no attitude variance in any message (ATTITUDE and ATTITUDE_QUATERNION
  have no such field; EKF_STATUS_REPORT's ``compass_variance`` is an innovation test ratio,
  AP_AHRS ``get_variances``), so there the configured sigma is all there is (docs/pose.md).
* ``ODOMETRY`` (PX4): its EKF's own attitude variance.  The prior's sigma is the larger of
  the configured one and the one reported (the newest within ``ODOMETRY_AGE_US``): the
  autopilot saying it is unsure (after a reset, a yaw it cannot observe) widens the prior;
  it never narrows it, since in the coupled loop that variance is itself fed by our fixes.
* ``LOCAL_POSITION_NED``: the EKF's height as NED down about the EKF origin, the frame the
  landmark map is placed in (GLOBAL_POSITION_INT's ``relative_alt`` is above *home*, which
  need not be the origin), interpolated, 1-sigma ``pose.altitude_sigma_m``; only with
  ``pose.use_altitude``.  With ``EK3_SRC1_POSZ = 6`` (ExtNav) the EKF's height is itself
  fed by our fixes: the sigma must then stay honest, as the attitude's does.  Its whole
  position, interpolated, serves acquisition alone (where to look while no fix comes:
  ``SideSensors.position_ned_m``).
* ``DISTANCE_SENSOR``: a range finder reading, the nearest sample (ranges jump between
  surfaces: never interpolated), along the beam its ``orientation`` names, 1-sigma
  ``pose.rangefinder_sigma_m``; only with ``pose.rangefinder``.  Readings outside the
  sensor's own ``min_distance .. max_distance`` are ignored.

Samples are stamped on the companion's clock (the frame's clock) from the autopilot's own
``time_boot_ms`` (:class:`~companion.boot_clock.BootClock`: the link's delay and a stall's
burst taken out); with :attr:`SensorHistory.boot_clock` None, with their arrival.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Sequence
from typing import Any

from companion.boot_clock import BootClock
from companion.nofix import AttitudeSource
from companion.side_sensors import SideSensors
from mavlink_bridge.bridge import VisionBridge
from tracker.pose.config import PoseConfig
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    RangeSample,
    laser_axis_from_mav_orientation,
)

#: The telemetry streams the pose uses (the bridge must ask the autopilot for them).
SENSOR_STREAMS = ("ATTITUDE", "LOCAL_POSITION_NED", "DISTANCE_SENSOR", "ODOMETRY")
#: How old the newest ODOMETRY may be for its attitude variance to count (asked at 5 Hz)
ODOMETRY_AGE_US = 1_000_000

Sample = tuple[int, tuple[float, ...]]  # (arrival time us, values)


def interpolate(samples: Sequence[Sample], t_us: int, max_gap_us: int,
                angles: Sequence[int] = ()) -> tuple[float, ...] | None:
    """The values at ``t_us`` between the two samples around it (the nearest one, within
    ``max_gap_us``, before the first or after the last); ``angles``: indices of values that
    wrap at 2 pi (interpolated the short way round).  None without a sample near enough."""
    if not samples:
        return None
    after = next((i for i, s in enumerate(samples) if s[0] >= t_us), None)
    if after is None or after == 0:
        near = samples[-1] if after is None else samples[0]
        return near[1] if abs(near[0] - t_us) <= max_gap_us else None
    (ta, a), (tb, b) = samples[after - 1], samples[after]
    if tb - ta > 2 * max_gap_us:
        return None  # a hole in the stream: neither side belongs to this frame
    f = (t_us - ta) / max(tb - ta, 1)
    out = []
    for i, (va, vb) in enumerate(zip(a, b, strict=True)):
        if i in angles:
            out.append(math.remainder(va + f * math.remainder(vb - va, math.tau), math.tau))
        else:
            out.append(va + f * (vb - va))
    return tuple(out)


def nearest(samples: Sequence[Sample], t_us: int, max_gap_us: int) -> tuple[float, ...] | None:
    """The values of the sample nearest to ``t_us`` within ``max_gap_us``, or None."""
    best = min(samples, key=lambda s: abs(s[0] - t_us), default=None)
    return None if best is None or abs(best[0] - t_us) > max_gap_us else best[1]


class SensorHistory:
    """Recent ATTITUDE, LOCAL_POSITION_NED, DISTANCE_SENSOR and ODOMETRY messages (see
    module doc).

    Called with a frame's capture time it returns the :class:`SideSensors` of that time.
    """

    def __init__(self, bridge: VisionBridge, config: PoseConfig | None = None,
                 keep: int = 200, attitude: AttitudeSource | None = None) -> None:
        self.bridge = bridge
        self.config = config or PoseConfig()
        #: where the attitude comes from instead of ATTITUDE (e.g. a recording's truth,
        #: ``companion run --truth-attitude``); None: the autopilot's
        self.attitude_source = attitude
        self.samples: dict[str, deque[Sample]] = {n: deque(maxlen=keep) for n in SENSOR_STREAMS}
        #: per stream, the messages received (for status and tests)
        self.received: dict[str, int] = dict.fromkeys(SENSOR_STREAMS, 0)
        #: maps the messages' ``time_boot_ms`` onto the companion's clock; None: stamp
        #: them with their arrival (a replay whose autopilot clock is stepped, not real time)
        self.boot_clock: BootClock | None = BootClock()
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Follow the bridge's streams until :meth:`stop`."""
        self._task = asyncio.create_task(self._follow(), name="sensor-history")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    async def _follow(self) -> None:
        async for item in self.bridge.subscribe(*SENSOR_STREAMS):
            t_us = item.received_ns // 1000
            if self.boot_clock is not None:
                t_us = self.boot_clock.stamp(int(getattr(item.value, "time_boot_ms", 0)), t_us)
            self.add(item.name, t_us, item.value)

    def add(self, name: str, t_us: int, v: Any) -> None:
        """Record one message's value (``Attitude``, ``LocalPositionNed``, ``DistanceSensor``,
        ``Odometry`` of :mod:`mavlink_bridge.telemetry`) of time ``t_us`` (companion clock)."""
        values: tuple[float, ...]
        if name == "ATTITUDE":
            values = (float(v.roll_rad), float(v.pitch_rad), float(v.yaw_rad))
        elif name == "LOCAL_POSITION_NED":
            values = (float(v.north_m), float(v.east_m), float(v.down_m))
        elif name == "DISTANCE_SENSOR":
            values = (float(v.distance_m), float(v.min_distance_m),
                      float(v.max_distance_m), float(v.orientation))
        elif name == "ODOMETRY":
            values = tuple(float(x) for x in v.attitude_variance_rad2)
        else:
            return
        self.samples[name].append((t_us, values))
        self.received[name] += 1

    def __call__(self, t_us: int) -> SideSensors:
        position = self.position_at(t_us)  # once: the height is its down
        return SideSensors(self.attitude_at(t_us), self._altitude(t_us, position),
                           self.range_at(t_us), position)

    def _gap_us(self) -> int:
        return round(self.config.max_sample_age_s * 1e6)

    def at(self, t_us: int, max_gap_us: int | None = None) -> AttitudeSample | None:
        """:class:`~companion.nofix.AttitudeSource`: the attitude at ``t_us``."""
        return self.attitude_at(t_us, max_gap_us)

    def last_us(self) -> int | None:
        """The newest attitude sample's time (companion clock, us); None before one."""
        if self.attitude_source is not None:
            return self.attitude_source.last_us()
        samples = self.samples["ATTITUDE"]
        return samples[-1][0] if samples else None

    def attitude_at(self, t_us: int, max_gap_us: int | None = None) -> AttitudeSample | None:
        """The autopilot's attitude at ``t_us`` with the configured sigmas, or None."""
        gap = self._gap_us() if max_gap_us is None else max_gap_us
        v: tuple[float, ...] | None
        if self.attitude_source is not None:
            sample = self.attitude_source.at(t_us, gap)
            v = None if sample is None else (sample.roll_rad, sample.pitch_rad, sample.yaw_rad)
        else:
            v = interpolate(list(self.samples["ATTITUDE"]), t_us, gap, angles=(0, 1, 2))
        if v is None:
            return None
        cfg = self.config
        roll_pitch = math.radians(cfg.attitude_roll_pitch_sigma_deg)
        yaw = math.radians(cfg.attitude_yaw_sigma_deg)
        odometry = self.samples["ODOMETRY"]  # the newest, not a copy scanned every frame
        if odometry and abs(odometry[-1][0] - t_us) <= ODOMETRY_AGE_US:
            var = odometry[-1][1]  # the autopilot's own variance: only ever wider (module doc)
            roll_pitch = max([roll_pitch, *(math.sqrt(x) for x in var[:2] if x >= 0.0)])
            yaw = max([yaw, *(math.sqrt(x) for x in var[2:] if x >= 0.0)])
        return AttitudeSample(t_us, v[0], v[1], v[2], roll_pitch, yaw)

    def altitude_at(self, t_us: int) -> AltitudeSample | None:
        """The EKF's NED down at ``t_us`` (``pose.use_altitude``), or None."""
        return self._altitude(t_us, self.position_at(t_us))

    def _altitude(self, t_us: int, position: tuple[float, float, float] | None
                  ) -> AltitudeSample | None:
        if not self.config.use_altitude or position is None:
            return None
        return AltitudeSample(t_us, position[2], self.config.altitude_sigma_m)

    def position_at(self, t_us: int) -> tuple[float, float, float] | None:
        """The EKF's position (NED about its origin) at ``t_us``, or None."""
        v = interpolate(list(self.samples["LOCAL_POSITION_NED"]), t_us, self._gap_us())
        return None if v is None else (v[0], v[1], v[2])

    def range_at(self, t_us: int) -> RangeSample | None:
        """The range finder's reading nearest to ``t_us`` (``pose.rangefinder``), or None."""
        if not self.config.rangefinder:
            return None
        v = nearest(list(self.samples["DISTANCE_SENSOR"]), t_us, self._gap_us())
        if v is None or not v[1] <= v[0] <= v[2]:
            return None
        try:
            axis = laser_axis_from_mav_orientation(int(v[3]))
        except ValueError:
            return None  # a beam direction the solver does not know
        return RangeSample(t_us, v[0], axis, self.config.rangefinder_sigma_m)
