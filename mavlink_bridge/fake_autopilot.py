"""A scripted fake autopilot (ArduPilot or PX4 flavour) as strict as the real ones.

It is first-class code: tests, ``companion demo`` and ``companion fake-autopilot`` use it.

* Flies ``truth(time_s) -> VehicleState`` (default: :func:`hover_then_circle`), or with
  ``vehicle="guided"`` a copter it flies itself from the companion's commands
  (:mod:`mavlink_bridge.fake_vehicle`).
* Streams (:mod:`mavlink_bridge.fake_streams`): by default (``streams="strict"``) only
  HEARTBEAT and PX4's TIMESYNC requests until asked with SET_MESSAGE_INTERVAL or
  REQUEST_MESSAGE; a reboot forgets the intervals.  Available: ATTITUDE,
  LOCAL_POSITION_NED, GLOBAL_POSITION_INT (0, 0 until the origin is set, like ArduPilot),
  SYSTEM_TIME, DISTANCE_SENSOR, EKF_STATUS_REPORT, HOME_POSITION (once the origin is set),
  and on PX4 ODOMETRY (the estimate with its attitude variance:
  ``reported_attitude_sigma_deg``).
* Its own estimator (:mod:`mavlink_bridge.fake_ekf`): LOCAL_POSITION_NED, GLOBAL_POSITION_INT,
  ATTITUDE and EKF_STATUS_REPORT report the estimate; fixes are gated against it, never
  against the truth.  Without fixes: "VisOdom: not healthy", flags 0x25, EKF failsafe LAND.
  Its height comes from a simulated barometer unless its parameters make the fixes the
  height source (:mod:`mavlink_bridge.fake_baro`: ``EK3_SRC1_POSZ`` 6, PX4 ``EKF2_EV_CTRL``
  bit 1).
* Parameters (:mod:`mavlink_bridge.fake_params`): PARAM_REQUEST_READ / _LIST / PARAM_SET
  with the real autopilot's defaults.
* The old permissive fake -- every stream unasked, fixes judged against the truth -- only
  with ``FakeAutopilotConfig.permissive()`` (``streams="all", judge="truth"``).
* Like a simulator, streams the *true* pose (``send_truth``): SIMSTATE and SIM_STATE in
  ArduPilot mode (SITL), HIL_STATE_QUATERNION in PX4 mode, at 50 Hz, as WGS84 about
  ``home`` (default: the EKF origin once set).  ``send_truth=False`` is a real vehicle.
* ACKs COMMAND_LONG/COMMAND_INT; the EKF origin (COMMAND_INT 611 for ArduPilot,
  SET_GPS_GLOBAL_ORIGIN for PX4) is accepted once, optionally after ``origin_fail_first``
  MAV_RESULT_FAILED answers as ArduPilot SITL gives while its EKF is not ready.
* Judges every VISION_POSITION_ESTIMATE / ODOMETRY / LANDING_TARGET with
  :mod:`mavlink_bridge.fake_rules` and records it (:attr:`FakeAutopilot.vision`).
* Enforces signing (with a key) and optionally ArduPilot's SYSID_ENFORCE.
* Faults: :meth:`drop_link`, :meth:`reboot`, :attr:`faults` (latency, jitter, loss, corruption).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pymap3d

from mavlink_bridge.codec import Codec, MAVLinkMessage
from mavlink_bridge.endpoint import Connection, open_connection, parse_endpoint
from mavlink_bridge.fake_baro import height_source
from mavlink_bridge.fake_drift import AttitudeDrift, AttitudeErrorConfig
from mavlink_bridge.fake_ekf import EstimatorConfig, FakeEstimator, estimator_defaults
from mavlink_bridge.fake_faults import FaultInjector
from mavlink_bridge.fake_params import FakeParams
from mavlink_bridge.fake_replay import TelemetryReplay
from mavlink_bridge.fake_report import fake_summary
from mavlink_bridge.fake_rules import (
    FakeRules,
    JitterCorrection,
    VisionJudge,
    VisionRecord,
    judge_landing_target,
    position_variances,
)
from mavlink_bridge.fake_streams import FakeStreams, StreamMode
from mavlink_bridge.fake_vehicle import (
    ARDUCOPTER_GUIDED,
    PX4_OFFBOARD,
    FlightState,
    GuidedVehicle,
)
from mavlink_bridge.params import param_name
from mavlink_bridge.telemetry import quaternion_from_rpy
from mavlink_bridge.vehicle import TruthFn, VehicleState, hover_then_circle

Profile = Literal["ardupilot", "px4"]
_EARTH_RADIUS_M = 6_378_137.0
MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED, MAV_RESULT_UNSUPPORTED = 0, 4, 3
_ALWAYS_ACCEPTED = {520}  # REQUEST_AUTOPILOT_CAPABILITIES
MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_REQUEST_MESSAGE = 511, 512
MAV_CMD_NAV_TAKEOFF, MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM = 22, 176, 400


def cm_s(v_m_s: float) -> int:
    """A velocity as GLOBAL_POSITION_INT's int16 cm/s, held to its range: an estimate that
    ran away (a coupled flight trusting its own fixes: 400 m/s seen) would otherwise stop
    the fake's stream thread with struct.error, where ArduPilot sends a wrapped value."""
    return max(-32768, min(32767, round(v_m_s * 100)))


@dataclass(frozen=True)
class FakeAutopilotConfig:
    profile: Profile = "ardupilot"
    endpoint: str = "udpin:127.0.0.1:0"
    system_id: int = 1
    signing_key: bytes | None = None
    sysid_enforce: bool = False
    origin_fail_first: int = 0
    timesync_samples_required: int = 500  # PX4 needs 500 good round trips
    timesync_max_rtt_ms: float = 10.0
    rules: FakeRules = field(default_factory=FakeRules)
    seed: int = 0
    # stream periods in seconds
    periods_s: tuple[tuple[str, float], ...] = (
        ("HEARTBEAT", 1.0), ("ATTITUDE", 0.05), ("LOCAL_POSITION_NED", 0.1),
        ("GLOBAL_POSITION_INT", 0.2), ("SYSTEM_TIME", 1.0), ("DISTANCE_SENSOR", 0.1),
        ("EKF_STATUS_REPORT", 0.5), ("TIMESYNC", 0.1), ("HOME_POSITION", 1.0),
        ("SIMSTATE", 0.02), ("SIM_STATE", 0.02), ("HIL_STATE_QUATERNION", 0.02),
        ("ODOMETRY", 0.1),
    )
    # the simulator's true pose (SIMSTATE/SIM_STATE or HIL_STATE_QUATERNION); off = a real
    # vehicle, which sends no truth
    send_truth: bool = True
    # where truth NED (0, 0, 0) is (lat_deg, lon_deg, alt_m); None: the EKF origin once set
    home: tuple[float, float, float] | None = None
    # the slowly varying error a real EKF's ATTITUDE (and GLOBAL_POSITION_INT's heading)
    # carries, on top of the estimator's coupled one (fake_drift: 1 deg roll/pitch, 3 deg yaw,
    # 1 deg/min yaw drift); None: the exact attitude.  Truth streams (SIM_STATE ...) stay exact.
    attitude_error: AttitudeErrorConfig | None = field(default_factory=AttitudeErrorConfig)
    # the (roll/pitch, yaw) 1-sigma PX4's ODOMETRY states for the attitude (its EKF's
    # orientation_variance); None: the error's own stationary sigmas (an honest EKF), 0.1 deg
    # without an error
    reported_attitude_sigma_deg: tuple[float, float] | None = None
    # DISTANCE_SENSOR's orientation (MAV_SENSOR_ORIENTATION): 25 (PITCH_270) a downward
    # range finder, ArduPilot's RNGFND1_ORIENT default; 0 (NONE) a forward one
    rangefinder_orientation: int = 25
    # "strict": nothing but HEARTBEAT (PX4: and TIMESYNC) until asked; "all": the old fake
    streams: StreamMode = "strict"
    # messages accepted for SET_MESSAGE_INTERVAL but never sent (a sensor not fitted)
    absent: tuple[str, ...] = ()
    # "estimate": the fake's own EKF gates the fixes; "truth": the old gate against truth
    judge: Literal["estimate", "truth"] = "estimate"
    # ArduPilot's jitter correction of vision stamps (fake_rules.JitterCorrection); off: a
    # fix is taken as made at its arrival, for a clock that is not a link's (`replay --fast`
    # runs the fake on the recording's time and stamps frames on the companion's)
    jitter_correction: bool = True
    # None: the profile's real defaults (fake_ekf.estimator_defaults)
    estimator: EstimatorConfig | None = None
    # "scripted": flies ``truth``, armed from the start (the flight is under way);
    # "guided": on the ground, disarmed, flown by the companion's commands
    vehicle: Literal["scripted", "guided"] = "scripted"
    # where the guided vehicle stands (north, east, down m, yaw deg): on the ground where its
    # camera sees two landmarks of the sample street, as a user points the camera at them
    # before arming (no fix, no arming: "PreArm: VisOdom: not healthy")
    guided_start: tuple[float, float, float, float] = (3.0, 0.0, 0.0, 60.0)
    # > 0: the guided vehicle starts hovering this high above its start, armed, in GUIDED /
    # OFFBOARD (as after a manual take-off): the sample street seen from the ground gives no
    # fix (docs/sitl.md), so the square-flight proofs start in the air
    guided_airborne_m: float = 0.0

    @classmethod
    def permissive(cls, **kw: Any) -> FakeAutopilotConfig:
        """The old fake: every stream without asking, fixes judged against the truth, the
        exact attitude."""
        return cls(**{"streams": "all", "judge": "truth", "attitude_error": None, **kw})


_TRUTH_BY_PROFILE: dict[str, tuple[str, ...]] = {
    "ardupilot": ("SIMSTATE", "SIM_STATE"), "px4": ("HIL_STATE_QUATERNION",),
}
_TRUTH_STREAMS = frozenset(n for names in _TRUTH_BY_PROFILE.values() for n in names)


@dataclass
class CompanionHeartbeat:
    arrival_s: float
    system_id: int
    component_id: int
    type: int
    autopilot: int
    system_status: int


class FakeAutopilot:
    """See module doc.  ``async with FakeAutopilot(cfg) as ap: ... ap.summary()``."""

    def __init__(self, config: FakeAutopilotConfig, truth: TruthFn | None = None,
                 clock_ns: Callable[[], int] = time.monotonic_ns,
                 replay: TelemetryReplay | None = None) -> None:
        """``replay``: a recording's telemetry, sent instead of the fake's own for the
        messages it holds (:mod:`mavlink_bridge.fake_replay`)."""
        self.config = config
        self.replay = replay
        self.truth: TruthFn = truth or hover_then_circle()
        if config.vehicle == "guided":
            n, e, d, yaw = config.guided_start
            vehicle = GuidedVehicle((n, e, d), math.radians(yaw))
            if config.guided_airborne_m > 0:
                vehicle.hover(config.guided_airborne_m)
            self.truth = vehicle
        self.clock_ns = clock_ns
        self.faults = FaultInjector(np.random.default_rng(config.seed), clock_ns)
        self.guided = self.truth if isinstance(self.truth, GuidedVehicle) else None
        airborne = self.guided is not None and config.guided_airborne_m > 0
        self.flight = FlightState(config.profile, armed=self.guided is None or airborne,
                                  custom_mode=self._guided_mode_number() if airborne else 0)
        self.params = FakeParams(config.profile)
        self.estimator_config = config.estimator or estimator_defaults(config.profile)
        self.streams = FakeStreams(config.streams, config.profile, config.periods_s,
                                   self._sendable(), config.absent)
        self.track: list[tuple[float, tuple[float, float, float],
                               tuple[float, float, float]]] = []  # (t, estimate, truth)
        self.attitude_drift = None if config.attitude_error is None else AttitudeDrift(
            config.attitude_error, config.seed)
        self.judge = VisionJudge(config.profile, config.rules)
        self.vision: list[VisionRecord] = []
        self.landing_targets: list[dict[str, Any]] = []
        self.commands: list[dict[str, Any]] = []
        self.position_targets: list[dict[str, Any]] = []  # SET_POSITION_TARGET_LOCAL_NED
        self.heartbeats: list[CompanionHeartbeat] = []
        self.statustexts: list[str] = []
        self.statustexts_sent: list[str] = []  # what this autopilot said
        self.counters: dict[str, int] = {"sysid_rejected": 0, "reboots": 0,
                                         "deprecated_origin_ignored": 0}
        self.connection: Connection | None = None
        self._start_ns = clock_ns()
        self._blind_until_ns = 0
        self._task: asyncio.Task[None] | None = None
        self._boot()

    def _boot(self) -> None:
        """(Re)boot: new sequence numbers and boot time; origin, time sync, EKF state lost."""
        self.codec = Codec(self.config.system_id, 1)
        if self.config.signing_key is not None:
            self.codec.enable_signing(self.config.signing_key, 0, ("RADIO_STATUS",))
        if self.connection is not None:
            self.codec.set_writer(self._tx)
        self.boot_ns = self.clock_ns()
        self.origin: tuple[float, float, float] | None = None
        self.origin_attempts = 0
        self.timesync_offset_ns = 0.0
        self.timesync_samples = 0
        self.jitter = JitterCorrection()  # ArduPilot's, per link: a reboot starts it anew
        self.judge.reset()
        self.streams.reset()  # a reboot forgets every asked interval
        self.ekf = FakeEstimator(self.estimator_config, self.config.seed)
        for pid in dict(self.params.sets):  # stored: a reboot keeps what the user set
            self.ekf.set_parameter(pid, self.params.values[pid], at_boot=True)
        self._last_track_s = -1.0
        self._prev_velocity: tuple[float, np.ndarray] | None = None

    def _sendable(self) -> frozenset[str]:
        names = {n for n, _ in self.config.periods_s if n not in _TRUTH_STREAMS}
        if self.config.send_truth:
            names |= set(_TRUTH_BY_PROFILE[self.config.profile])
        if self.config.profile != "px4":
            names -= {"TIMESYNC", "ODOMETRY"}  # ArduPilot sends no ODOMETRY
        return frozenset(names)

    # ------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        self.connection = await open_connection(parse_endpoint(self.config.endpoint),
                                                self._rx)
        self.codec.set_writer(self._tx)
        self._task = asyncio.create_task(self._stream_loop(), name="fake-autopilot")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        self.faults.cancel_pending()
        if self.connection is not None:
            self.connection.close()

    async def __aenter__(self) -> FakeAutopilot:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    @property
    def local_port(self) -> int:
        return 0 if self.connection is None else self.connection.local_port

    def boot_s(self) -> float:
        return (self.clock_ns() - self.boot_ns) * 1e-9

    @property
    def start_ns(self) -> int:
        """When the flight began (``truth`` time 0) on the autopilot's clock."""
        return self._start_ns

    def flight_s(self) -> float:
        return (self.clock_ns() - self._start_ns) * 1e-9

    @property
    def timesync_synced(self) -> bool:
        return self.timesync_samples >= self.config.timesync_samples_required

    # ------------------------------------------------------------ faults
    def drop_link(self, seconds: float) -> None:
        """Nothing passes in either direction for ``seconds``."""
        self.faults.state.drop_until_ns = self.clock_ns() + int(seconds * 1e9)

    def blind(self, seconds: float) -> None:
        """A vision outage: for ``seconds`` every incoming vision message is dropped
        (counted as ``vision_blinded``), as if the companion's fixes stopped."""
        self._blind_until_ns = self.clock_ns() + int(seconds * 1e9)

    def reboot(self, silent_s: float = 1.0) -> None:
        """Reboot: silent for ``silent_s``, then sequence 0, boot time 0, no origin."""
        self.counters["reboots"] += 1
        self.params.reboot_done()
        self.drop_link(silent_s)
        self._boot()
        self.boot_ns += int(silent_s * 1e9)

    # ------------------------------------------------------------ transmit
    def _tx(self, data: bytes) -> None:
        if self.connection is not None:
            self.faults.apply(data, self.connection.write, corrupt=True)

    async def _stream_loop(self) -> None:
        while True:
            self.tick()
            await asyncio.sleep(0.01)

    def tick(self) -> None:
        """Fly to now and send what is due (every 10 ms; a replay on a driven clock calls
        it after each step of its clock)."""
        state = self._advance(self.flight_s())
        if not self.faults.link_down():
            for name in self.streams.due(self.boot_s()):
                if name in _TRUTH_STREAMS and (self.config.home or self.origin) is None:
                    continue
                self._send_stream(name, state)
            if self.replay is not None:
                self.replay.pump(self.codec.mav, self.streams.periods, self.flight_s(),
                                 int(self.boot_s() * 1000) & 0xFFFFFFFF)

    def send_heartbeat(self) -> None:
        """One HEARTBEAT now, outside the stream schedule (``replay --fast``'s pre-roll,
        where the fake's clock stands, brings the link up with it)."""
        if not self.faults.link_down():
            self._send_stream("HEARTBEAT", self.truth(self.flight_s()))

    def _advance(self, t: float) -> VehicleState:
        """Fly, propagate the estimator with the IMU, run the EKF failsafe; -> the truth."""
        if self.guided is not None:
            self.guided.step_to(t)
            if self.flight.landing and self.guided.on_ground() and self.flight.armed:
                self.flight.arm(t, False, True, self._text)
            accel = self.guided.acceleration()
        state = self.truth(t)
        if self.guided is None:  # the IMU of a scripted flight: d(velocity)/dt of the truth
            v, prev = np.asarray(state.velocity_ned_m_s), self._prev_velocity
            accel = np.zeros(3) if prev is None or t - prev[0] < 1e-3 \
                else (v - prev[1]) / (t - prev[0])
            self._prev_velocity = (t, v)
        self.ekf.predict(t, accel)
        if self.estimator_config.height_source != "fixes":  # the old fake's only on request
            self.ekf.height_source = height_source(self.config.profile, self.params.values)
        self.ekf.observe_baro(t, state.position_ned_m[2])
        if self.config.judge == "estimate":
            # a vehicle flying from the start (scripted, or guided airborne) had its position
            # before this fake began: the failsafe watches outages after the first fix
            ok = self.ekf.horizontal_ok(t) or not self.ekf.initialised
            self.flight.check_ekf(t, ok, self._text)
        if self.guided is not None:
            self.guided.landing = self.flight.landing
        if self.ekf.initialised and t - self._last_track_s >= 0.1:
            self._last_track_s = t
            self.track.append((t, self.ekf.position(), state.position_ned_m))
        return state

    def _text(self, text: str) -> None:
        self.statustexts_sent.append(text)
        self.codec.mav.statustext_send(4, text.encode()[:50])

    def _send_truth(self, name: str, s: VehicleState) -> None:
        """The simulator's true pose as WGS84 (pymap3d, the same geodesy as the companion)."""
        home = self.config.home or self.origin
        assert home is not None
        lat, lon, alt = (float(v) for v in pymap3d.ned2geodetic(*s.position_ned_m, *home))
        r, p, y = s.attitude_rpy_rad
        vn, ve, vd = s.velocity_ned_m_s
        q = quaternion_from_rpy(r, p, y)
        mav = self.codec.mav
        lat7, lon7 = round(lat * 1e7), round(lon * 1e7)
        if name == "SIMSTATE":
            mav.simstate_send(r, p, y, 0.0, 0.0, -9.80665, 0.0, 0.0, 0.0, lat7, lon7)
        elif name == "SIM_STATE":
            mav.sim_state_send(*q, r, p, y, 0.0, 0.0, -9.80665, 0.0, 0.0, 0.0, lat, lon, alt,
                               0.0, 0.0, vn, ve, vd, lat7, lon7)
        else:
            mav.hil_state_quaternion_send(
                self._local_ns() // 1000, list(q), 0.0, 0.0, 0.0, lat7, lon7, round(alt * 1000),
                round(vn * 100), round(ve * 100), round(vd * 100), 0, 0, 0, 0, -1000)

    def _send_stream(self, name: str, s: VehicleState) -> None:
        if name in _TRUTH_STREAMS:
            self._send_truth(name, s)
            return
        mav = self.codec.mav
        boot_ms = int(self.boot_s() * 1000) & 0xFFFFFFFF
        if self.replay is not None and self.replay.covers(name):
            return  # sent by the replay at its recorded times (tick)
        own = self.config.judge == "estimate"
        if own and self.origin is None and name == "LOCAL_POSITION_NED":
            return  # no origin, no local position (ArduPilot: get_relative_position_NED_origin)
        n, e, d = self.ekf.position() if own else s.position_ned_m
        vn, ve, vd = self.ekf.velocity() if own else s.velocity_ned_m_s
        r, p, y = self.ekf.attitude(s.attitude_rpy_rad) if own else s.attitude_rpy_rad
        if self.attitude_drift is not None:
            er, ep, ey = self.attitude_drift.error(s.time_s)
            r, p, y = r + er, p + ep, math.remainder(y + ey, math.tau)
        if name == "HEARTBEAT":
            ap = 3 if self.config.profile == "ardupilot" else 12  # ARDUPILOTMEGA / PX4
            base, custom, status = self.flight.heartbeat()
            mav.heartbeat_send(2, ap, base, custom, status)  # QUADROTOR
        elif name == "ATTITUDE":
            mav.attitude_send(boot_ms, r, p, y, 0.0, 0.0, 0.0)
        elif name == "LOCAL_POSITION_NED":
            mav.local_position_ned_send(boot_ms, n, e, d, vn, ve, vd)
        elif name == "GLOBAL_POSITION_INT":
            lat, lon, alt = self._global(n, e, d)
            mav.global_position_int_send(boot_ms, lat, lon, alt, round(-d * 1000),
                                         *(cm_s(v) for v in (vn, ve, vd)),
                                         round(math.degrees(y) % 360 * 100))
        elif name == "SYSTEM_TIME":
            mav.system_time_send(int(time.time() * 1e6), boot_ms)
        elif name == "DISTANCE_SENSOR":
            mav.distance_sensor_send(boot_ms, 20, 4000, round(s.range_m * 100), 0, 0,
                                     self.config.rangefinder_orientation, 0)
        elif name == "EKF_STATUS_REPORT" and self.config.profile == "ardupilot":
            flags = self.ekf.flags(self.flight_s(), self.origin is not None) if own \
                else (0x33F if self.origin is not None else 0x07)
            mav.ekf_status_report_send(flags, 0.1, 0.1, 0.1, 0.1, 0.0)
        elif name == "TIMESYNC":
            mav.timesync_send(0, self._local_ns())
        elif name == "ODOMETRY":  # PX4's: position, attitude and their variances
            cov, (tilt_deg, yaw_deg) = [math.nan] * 21, self._reported_sigmas_deg()
            cov[15] = cov[18] = math.radians(tilt_deg) ** 2
            cov[20] = math.radians(yaw_deg) ** 2
            mav.odometry_send(self._local_ns() // 1000, 1, 12, n, e, d,  # LOCAL_NED, BODY_FRD
                              list(quaternion_from_rpy(r, p, y)), vn, ve, vd, 0.0, 0.0, 0.0,
                              cov, [math.nan] * 21, 0, 8)  # MAV_ESTIMATOR_TYPE_AUTOPILOT
        elif name == "HOME_POSITION" and self.origin is not None:
            lat, lon, alt = self._global(0.0, 0.0, 0.0)
            mav.home_position_send(lat, lon, alt, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0],
                                   0.0, 0.0, 0.0)

    def _reported_sigmas_deg(self) -> tuple[float, float]:
        """The attitude 1-sigma ODOMETRY states (roll/pitch, yaw; the config's)."""
        if self.config.reported_attitude_sigma_deg is not None:
            return self.config.reported_attitude_sigma_deg
        err = self.config.attitude_error
        return (0.1, 0.1) if err is None else (err.roll_pitch_sigma_deg, err.yaw_sigma_deg)

    def _local_ns(self) -> int:
        return self.clock_ns() - self.boot_ns

    def _global(self, n: float, e: float, d: float) -> tuple[int, int, int]:
        if self.origin is None:
            return 0, 0, 0
        lat0, lon0, alt0 = self.origin
        lat = lat0 + math.degrees(n / _EARTH_RADIUS_M)
        lon = lon0 + math.degrees(e / (_EARTH_RADIUS_M * math.cos(math.radians(lat0))))
        return round(lat * 1e7), round(lon * 1e7), round((alt0 - d) * 1000)

    # ------------------------------------------------------------ receive
    def _rx(self, data: bytes) -> None:
        self.faults.apply(data, self._process, corrupt=False)

    def _process(self, data: bytes) -> None:
        if self.connection is None:
            return
        for msg in self.codec.feed(data, self.connection.endpoint.datagram):
            sysid = msg.get_srcSystem()
            if self.config.sysid_enforce and sysid not in (self.config.system_id, 255):
                self.counters["sysid_rejected"] += 1
                continue
            try:
                self._handle(msg)
            except Exception:  # a fake must survive whatever the companion sends
                self.counters["handler_errors"] = self.counters.get("handler_errors", 0) + 1

    def _handle(self, msg: MAVLinkMessage) -> None:
        name = msg.get_type()
        if name in ("VISION_POSITION_ESTIMATE", "ODOMETRY"):
            if self.clock_ns() < self._blind_until_ns:
                self.counters["vision_blinded"] = self.counters.get("vision_blinded", 0) + 1
                return
            self._on_vision(name, msg)
        elif name == "LANDING_TARGET":
            ok, why = judge_landing_target(self.config.profile, msg.to_dict())
            self.landing_targets.append({**msg.to_dict(), "arrival_s": self.boot_s(),
                                         "accepted": ok, "reason": why})
        elif name == "HEARTBEAT":
            self.heartbeats.append(CompanionHeartbeat(
                self.flight_s(), msg.get_srcSystem(), msg.get_srcComponent(), msg.type,
                msg.autopilot, msg.system_status))
        elif name in ("COMMAND_INT", "COMMAND_LONG"):
            self._on_command(name, msg)
        elif name == "SET_POSITION_TARGET_LOCAL_NED":
            self.position_targets.append({**msg.to_dict(), "arrival_s": self.boot_s()})
            if self.guided is not None and self.flight.armed and self._guided_mode():
                self.guided.goto((msg.x, msg.y, msg.z), msg.yaw)
        elif name.startswith("PARAM_"):
            self.params.handle(name, msg, self.codec.mav)
            pid = param_name(msg.param_id) if name == "PARAM_SET" else ""
            if pid in self.params.values:
                self.ekf.set_parameter(pid, self.params.values[pid])  # read at every fix
        elif name == "SET_GPS_GLOBAL_ORIGIN":
            if self.config.profile == "px4":
                self._set_origin(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
            else:
                self.counters["deprecated_origin_ignored"] += 1
        elif name == "TIMESYNC":
            self._on_timesync(msg)
        elif name == "STATUSTEXT":
            self.statustexts.append(str(msg.text))

    def _on_timesync(self, msg: MAVLinkMessage) -> None:
        now = self._local_ns()
        if msg.tc1 == 0:
            self.codec.mav.timesync_send(now, msg.ts1)
            return
        rtt_ns = now - msg.ts1
        if not 0 <= rtt_ns < self.config.timesync_max_rtt_ms * 1e6:
            return
        offset = (msg.ts1 + now) / 2 - msg.tc1  # local - remote
        k = self.timesync_samples
        self.timesync_offset_ns = offset if k == 0 else 0.9 * self.timesync_offset_ns + 0.1 * offset
        self.timesync_samples += 1

    def _stamp_age_ms(self, stamp_us: int, now_ns: int | None = None) -> float:
        """How old the sample is in our clock at ``now_ns`` (our time since boot; now when
        omitted): ArduPilot's jitter correction (the stamp plus the smallest transport lag
        seen, :class:`JitterCorrection`); PX4 converts with the TIMESYNC offset once synced,
        else uses the arrival time."""
        now_ns = self._local_ns() if now_ns is None else now_ns
        if self.config.profile == "ardupilot":
            return self.jitter.age_ms(stamp_us, now_ns // 1000) \
                if self.config.jitter_correction else 0.0
        if not self.timesync_synced:
            return 0.0
        local_us = stamp_us + self.timesync_offset_ns / 1000
        return (now_ns / 1000 - local_us) / 1000

    def _on_vision(self, name: str, msg: MAVLinkMessage) -> None:
        arrival_ns = self._local_ns()  # one instant for the age and the record
        f = msg.to_dict()
        stamp = int(f["time_usec"] if name == "ODOMETRY" else f["usec"])
        age_ms = self._stamp_age_ms(stamp, arrival_ns)
        delay_s = self.ekf.delay_ms / 1000 if self.config.judge == "estimate" \
            else self.config.rules.delay_ms / 1000
        truth = self.truth(self.flight_s() - delay_s - max(age_ms, 0) / 1000)
        pos = (float(f["x"]), float(f["y"]), float(f["z"]))
        if self.config.judge == "truth":
            ok, why, innov = self.judge.judge(name, f, truth, age_ms)
        else:
            ok, why, innov = self._fuse(name, f, pos, age_ms)
        self.vision.append(VisionRecord(
            name=name, arrival_s=arrival_ns * 1e-9, time_usec=stamp, position_ned_m=pos,
            frame_id=int(f.get("frame_id", 1)), child_frame_id=int(f.get("child_frame_id", 0)),
            estimator_type=int(f.get("estimator_type", 0)), quality=int(f.get("quality", 0)),
            reset_counter=int(f.get("reset_counter", 0)), accepted=ok, reason=why,
            innovation_m=innov,
            stamp_age_ms=age_ms if self.timesync_synced or self.config.profile == "ardupilot"
            else math.nan,
            truth_error_m=math.dist(pos, truth.position_ned_m)))

    def _fuse(self, name: str, f: dict[str, Any], pos: tuple[float, float, float],
              age_ms: float) -> tuple[bool, str, float]:
        """The real rules, then the estimator's gate against its own estimate."""
        reason, reset = self.judge.screen(name, f, age_ms)
        if reason is not None:
            return False, reason, math.nan
        now_s = self.flight_s()
        verdict = self.ekf.fuse(now_s - max(age_ms, 0) / 1000, pos,
                                position_variances(name, f), reset, now_s=now_s)
        return verdict.accepted, verdict.reason, verdict.innovation_m

    def _on_command(self, name: str, msg: MAVLinkMessage) -> None:
        cmd = int(msg.command)
        if cmd == 611 and name == "COMMAND_INT" and self.config.profile == "ardupilot":
            result = self._origin_command(msg)
        else:
            result = self._command(cmd, float(msg.param1), float(msg.param2),
                                   float(msg.param3), float(getattr(msg, "param7", 0.0)))
        self.commands.append({"kind": name, "command": cmd, "result": result,
                              "arrival_s": self.boot_s(), "param1": float(msg.param1),
                              "param2": float(msg.param2)})
        self.codec.mav.command_ack_send(cmd, result, 0, 0, msg.get_srcSystem(),
                                        msg.get_srcComponent())

    def _command(self, cmd: int, p1: float, p2: float, p3: float, p7: float) -> int:
        t = self.flight_s()
        if cmd == MAV_CMD_SET_MESSAGE_INTERVAL:
            return self.streams.set_interval(int(p1), p2)
        if cmd == MAV_CMD_REQUEST_MESSAGE:
            return self.streams.request_once(int(p1))
        if cmd == MAV_CMD_DO_SET_MODE:
            return self.flight.set_mode(t, p2, p3)
        if cmd == MAV_CMD_COMPONENT_ARM_DISARM:
            ok = self.config.judge == "truth" or (self.ekf.initialised
                                                  and self.ekf.horizontal_ok(t))
            return self.flight.arm(t, p1 == 1.0, ok, self._text)
        if cmd == MAV_CMD_NAV_TAKEOFF:
            if self.guided is not None and self.flight.armed and self._guided_mode():
                self.guided.takeoff(p7)
            return MAV_RESULT_ACCEPTED
        return MAV_RESULT_ACCEPTED if cmd in _ALWAYS_ACCEPTED else MAV_RESULT_UNSUPPORTED

    def _guided_mode_number(self) -> int:
        return ARDUCOPTER_GUIDED if self.config.profile == "ardupilot" else PX4_OFFBOARD

    def _guided_mode(self) -> bool:
        return (self.flight.custom_mode == self._guided_mode_number()
                and self.flight.failsafe is None)

    def _origin_command(self, msg: MAVLinkMessage) -> int:
        if self.origin is not None:
            return MAV_RESULT_FAILED  # it can be set once
        self.origin_attempts += 1
        if self.origin_attempts <= self.config.origin_fail_first:
            return MAV_RESULT_FAILED  # EKF not ready yet, like SITL right after boot
        self._set_origin(msg.x * 1e-7, msg.y * 1e-7, float(msg.z))
        return MAV_RESULT_ACCEPTED

    def _set_origin(self, lat: float, lon: float, alt_m: float) -> None:
        if self.origin is not None:
            return
        self.origin = (lat, lon, alt_m)
        self.codec.mav.gps_global_origin_send(round(lat * 1e7), round(lon * 1e7),
                                              round(alt_m * 1000), self._local_ns() // 1000)
        self.codec.mav.statustext_send(6, b"EKF3 IMU0 origin set")

    # ------------------------------------------------------------ results
    def accepted(self) -> list[VisionRecord]:
        return [r for r in self.vision if r.accepted]

    def summary(self) -> dict[str, Any]:
        """Everything a test or a user wants to know, JSON-serialisable."""
        return fake_summary(self)
