"""The autopilot parameters a profile needs, their real defaults, and the read/set protocol.

Table per profile: the value the companion wants, the autopilot's own default (what an
unconfigured vehicle has) and whether a change needs a reboot.  Sources:

* ArduPilot: ``VISO_TYPE`` default 0, reboot required; ``VISO_DELAY_MS`` default 10;
  ``VISO_POS_M_NSE`` default 0.2 (libraries/AP_VisualOdom/AP_VisualOdom.cpp);
  ``EK3_SRC1_POSXY`` 3 (GPS), ``EK3_SRC1_VELXY`` 3, ``EK3_SRC1_POSZ`` 1 (baro),
  ``EK3_SRC1_VELZ`` 3, ``EK3_SRC1_YAW`` 1 (compass) (libraries/AP_NavEKF/AP_NavEKF_Source.cpp);
  ``GPS1_TYPE`` 1 (auto), reboot required (libraries/AP_GPS/AP_GPS.cpp).
* PX4: ``EKF2_EV_CTRL`` 0 (src/modules/ekf2/params_external_vision.yaml, no vision fusion),
  ``EKF2_EV_DELAY`` 0 ms, ``EKF2_EVP_NOISE`` 0.1 m, ``EKF2_EV_NOISE_MD`` 0,
  ``EKF2_GPS_CTRL`` 7, ``EKF2_HGT_REF`` 1 (GNSS; 0 baro, 3 vision; reboot required,
  src/modules/ekf2/ekf2_params.c ``@reboot_required true``); the other EKF2
  parameters apply without a reboot.

Protocol (MAVLink parameter microservice): PARAM_REQUEST_READ by name (param_index -1) is
answered with PARAM_VALUE; PARAM_SET is answered with PARAM_VALUE carrying the value now in
force (the read-back).  Names are at most 16 characters, values float32 on the wire.  An
INT32 parameter travels as its value cast to float on ArduPilot (C-cast encoding) but as its
four bytes reinterpreted as a float on PX4 (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE;
src/modules/mavlink/mavlink_parameters.cpp): :func:`encode_value` / :func:`decode_value`.
"""

from __future__ import annotations

import asyncio
import struct
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

MAV_PARAM_TYPE_INT32, MAV_PARAM_TYPE_REAL32 = 6, 9
#: VISO_DELAY_MS / EKF2_EV_DELAY when the companion's latency was never measured: the
#: capture-to-wire p50 seen on a loaded laptop (docs/sitl.md) plus a margin.
DEFAULT_DELAY_MS = 60.0
#: How far ArduPilot's EKF3 fuses behind now at least: its fusion time horizon with the
#: default sensor delays, max(EK3_HGT_DELAY 60, EK3_FLOW_DELAY 10, EK3_BCN_DELAY 50,
#: EKF_TARGET_DT_MS 12) ms; with external navigation on, max(this, min(VISO_DELAY_MS, 250))
#: (NavEKF3_core::setup_core).  A fix stamped older is taken as made at the horizon
#: (writeExtNavData): mavlink_bridge/fake_ekf.py, docs/mavlink.md "Timestamps".
EKF3_HORIZON_FLOOR_MS = 60.0


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: what the companion wants, the autopilot's default, reboot needed."""

    name: str
    wanted: float
    default: float
    reboot: bool
    why: str
    integer: bool = True


def parameter_specs(profile: str, delay_ms: float | None = None) -> tuple[ParamSpec, ...]:
    """The table of ``profile`` with the delay parameter from ``delay_ms`` (the measured
    capture-to-wire latency; None: :data:`DEFAULT_DELAY_MS`)."""
    delay = round(DEFAULT_DELAY_MS if delay_ms is None else delay_ms)
    if profile == "px4":
        return (
            ParamSpec("EKF2_EV_CTRL", 1, 0, False, "fuse vision horizontal position"),
            ParamSpec("EKF2_EV_DELAY", delay, 0, False, "the companion's latency", False),
            ParamSpec("EKF2_EV_NOISE_MD", 0, 0, False, "use the fixes' covariances"),
            ParamSpec("EKF2_EVP_NOISE", 0.1, 0.1, False, "position noise floor (m)", False),
            ParamSpec("EKF2_GPS_CTRL", 0, 7, False, "no GPS: position from vision only"),
            ParamSpec("EKF2_HGT_REF", 0, 1, True, "height from the barometer"),
        )
    return (
        ParamSpec("VISO_TYPE", 1, 0, True, "MAVLink external navigation"),
        ParamSpec("VISO_DELAY_MS", delay, 10, False, "the companion's latency (ms)"),
        ParamSpec("VISO_POS_M_NSE", 0.1, 0.2, False, "position noise floor (m)", False),
        ParamSpec("EK3_SRC1_POSXY", 6, 3, False, "horizontal position from the fixes"),
        ParamSpec("EK3_SRC1_VELXY", 0, 3, False, "no velocity source (position only)"),
        ParamSpec("EK3_SRC1_POSZ", 1, 1, False, "height from the barometer"),
        ParamSpec("EK3_SRC1_VELZ", 0, 3, False, "no vertical velocity source"),
        ParamSpec("EK3_SRC1_YAW", 1, 1, False, "yaw from the compass"),
        ParamSpec("GPS1_TYPE", 0, 1, True, "no GPS (the companion sets the EKF origin)"),
    )


def profile_parameters(profile: str, delay_ms: float | None = None) -> dict[str, float]:
    """Name -> the value the companion wants (for ``companion check`` and ``autopilot
    setup``)."""
    return {p.name: float(p.wanted) for p in parameter_specs(profile, delay_ms)}


def autopilot_defaults(profile: str) -> dict[str, float]:
    """Name -> the real autopilot's default (the fake autopilot starts with these)."""
    return {p.name: float(p.default) for p in parameter_specs(profile)}


def needs_reboot(profile: str, names: list[str]) -> list[str]:
    """Which of ``names`` take effect only after a reboot."""
    reboot = {p.name for p in parameter_specs(profile) if p.reboot}
    return [n for n in names if n in reboot]


def same_value(a: float, b: float) -> bool:
    """Equal as float32 on the wire (0.1 comes back as 0.100000001)."""
    return abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))


def encode_value(value: float, integer: bool, bytewise: bool) -> float:
    """The float32 field that carries ``value``."""
    if integer and bytewise:
        return float(struct.unpack("<f", struct.pack("<i", round(value)))[0])
    return float(value)


def decode_value(raw: float, param_type: int, bytewise: bool) -> float:
    """The value a PARAM_VALUE carries."""
    if param_type == MAV_PARAM_TYPE_INT32 and bytewise:
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    return float(raw)


def param_name(raw: Any) -> str:
    """PARAM_VALUE.param_id as str (pymavlink gives str; bytes from other decoders)."""
    text = raw.decode("ascii", "replace") if isinstance(raw, bytes) else str(raw)
    return text.rstrip("\x00")


class ParamLink(Protocol):
    """What the protocol needs of a link: send by name, the autopilot's sysid, and a
    subscription to every PARAM_VALUE."""

    autopilot_sysid: int | None

    def send(self, name: str, **fields: Any) -> None: ...
    def add_msg_listener(self, fn: Any) -> None: ...
    def remove_msg_listener(self, fn: Any) -> None: ...


class ParamClient:
    """Read and set parameters by name over a :class:`ParamLink`, retrying each request."""

    def __init__(self, link: ParamLink, timeout_s: float = 1.0, retries: int = 3,
                 bytewise: bool = False) -> None:
        self.link = link
        self.bytewise = bytewise
        self.timeout_s = timeout_s
        self.retries = retries
        self.values: dict[str, float] = {}
        self._seen: dict[str, float] = {}

    def _on_msg(self, msg: Any) -> None:
        if msg.get_type() == "PARAM_VALUE":
            name = param_name(msg.param_id)
            self.values[name] = decode_value(float(msg.param_value), int(msg.param_type),
                                             self.bytewise)
            self._seen[name] = time.monotonic()

    async def _exchange(self, names: list[str], send: Any) -> dict[str, float | None]:
        self.link.add_msg_listener(self._on_msg)
        try:
            out: dict[str, float | None] = {}
            for name in names:
                out[name] = None
                for _ in range(self.retries):
                    asked = time.monotonic()
                    send(name)
                    deadline = asked + self.timeout_s
                    while time.monotonic() < deadline:
                        if self._seen.get(name, 0.0) >= asked:
                            out[name] = self.values[name]
                            break
                        await asyncio.sleep(0.01)
                    if out[name] is not None:
                        break
            return out
        finally:
            self.link.remove_msg_listener(self._on_msg)

    async def read(self, names: list[str]) -> dict[str, float | None]:
        """Name -> value (None: no answer after the retries)."""
        target = self.link.autopilot_sysid or 1
        return await self._exchange(names, lambda n: self.link.send(
            "PARAM_REQUEST_READ", target_system=target, target_component=1,
            param_id=n.encode("ascii"), param_index=-1))

    async def set(self, values: Mapping[str, float], integer: Mapping[str, bool]
                  ) -> dict[str, float | None]:
        """Set each and return the value the autopilot answers with (the read-back)."""
        target = self.link.autopilot_sysid or 1
        return await self._exchange(list(values), lambda n: self.link.send(
            "PARAM_SET", target_system=target, target_component=1,
            param_id=n.encode("ascii"),
            param_value=encode_value(values[n], integer.get(n, False), self.bytewise),
            param_type=MAV_PARAM_TYPE_INT32 if integer.get(n, False) else MAV_PARAM_TYPE_REAL32))


async def read_parameters(link: ParamLink, names: list[str], profile: str,
                          timeout_s: float = 1.0) -> dict[str, float | None]:
    """Read ``names`` from the ``profile`` autopilot on ``link`` (for ``companion check``)."""
    return await ParamClient(link, timeout_s, bytewise=profile == "px4").read(names)
