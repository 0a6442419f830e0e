"""The fake autopilot's parameters: the profile's table with the real autopilot's defaults.

Answers PARAM_REQUEST_READ (by name or index), PARAM_REQUEST_LIST (every parameter) and
PARAM_SET (stores the value, answers PARAM_VALUE with it: the read-back) as ArduPilot's
libraries/GCS_MAVLink/GCS_Param.cpp and PX4's src/modules/mavlink/mavlink_parameters.cpp do.
An unknown name gets no answer (both autopilots stay silent).  Values survive a reboot
(they are stored); :attr:`FakeParams.pending_reboot` lists the set ones that need a reboot
to take effect.
"""

from __future__ import annotations

from typing import Any

from mavlink_bridge.params import (
    MAV_PARAM_TYPE_INT32,
    MAV_PARAM_TYPE_REAL32,
    decode_value,
    encode_value,
    param_name,
    parameter_specs,
)


class FakeParams:
    """Parameter storage and the PARAM_* answers of one fake autopilot."""

    def __init__(self, profile: str) -> None:
        self.profile = profile
        self.bytewise = profile == "px4"
        specs = parameter_specs(profile)
        self.values: dict[str, float] = {p.name: float(p.default) for p in specs}
        self.integer = {p.name: p.integer for p in specs}
        self.reboot = {p.name for p in specs if p.reboot}
        self.pending_reboot: set[str] = set()
        self.sets: list[tuple[str, float]] = []

    def reboot_done(self) -> None:
        self.pending_reboot.clear()

    def handle(self, name: str, msg: Any, mav: Any) -> None:
        """One PARAM_* message; answers through ``mav`` (pymavlink's MAVLink object)."""
        if name == "PARAM_REQUEST_LIST":
            for i in range(len(self.values)):
                self._send(mav, list(self.values)[i])
        elif name == "PARAM_REQUEST_READ":
            pid = param_name(msg.param_id)
            if msg.param_index >= 0 and msg.param_index < len(self.values):
                pid = list(self.values)[msg.param_index]
            if pid in self.values:
                self._send(mav, pid)
        elif name == "PARAM_SET":
            pid = param_name(msg.param_id)
            if pid not in self.values:
                return
            value = decode_value(float(msg.param_value), int(msg.param_type), self.bytewise)
            if self.integer[pid]:
                value = float(round(value))
            if value != self.values[pid] and pid in self.reboot:
                self.pending_reboot.add(pid)
            self.values[pid] = value
            self.sets.append((pid, value))
            self._send(mav, pid)

    def _send(self, mav: Any, pid: str) -> None:
        integer = self.integer[pid]
        names = list(self.values)
        mav.param_value_send(pid.encode("ascii"),
                             encode_value(self.values[pid], integer, self.bytewise),
                             MAV_PARAM_TYPE_INT32 if integer else MAV_PARAM_TYPE_REAL32,
                             len(names), names.index(pid))
