"""The fake autopilot's telemetry replay (mavlink_bridge/fake_replay.py): recorded messages
at their recorded times, only when asked, thinned to the asked interval, never twice, with
the fake's own time_boot_ms."""

from __future__ import annotations

from typing import Any

from mavlink_bridge.fake_replay import RecordedMessage, TelemetryReplay


class _Mav:
    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []

    def __getattr__(self, name: str) -> Any:
        return lambda **fields: self.sent.append((name, fields))


def _attitudes(times_s: list[float]) -> TelemetryReplay:
    return TelemetryReplay([RecordedMessage(t, "ATTITUDE", {"time_boot_ms": 7, "roll": 0.0,
                                                            "pitch": 0.0, "yaw": t})
                            for t in times_s])


def test_recorded_messages_go_out_when_asked_at_their_time_thinned_never_twice() -> None:
    replay = _attitudes([0.00, 0.02, 0.04, 0.06, 0.08, 0.10])
    replay.start(offset_s=1.0)  # recording time 0 = the fake's flight time 1 s
    mav = _Mav()
    assert replay.pump(mav, {}, 1.05, 500) == 0  # not asked: nothing
    periods = {"ATTITUDE": 0.04}  # asked at 25 Hz
    assert replay.pump(mav, periods, 1.05, 1050) == 1  # the newest by then: t = 0.04
    assert replay.pump(mav, periods, 1.05, 1050) == 0  # never twice
    assert replay.pump(mav, periods, 1.065, 1065) == 0  # 0.06 is 0.02 after: thinned
    assert replay.pump(mav, periods, 1.085, 1085) == 1  # 0.08: 0.04 after
    assert [f["yaw"] for _, f in mav.sent] == [0.04, 0.08]
    assert [f["time_boot_ms"] for _, f in mav.sent] == [1050, 1085]  # the fake's own clock
    assert {name for name, _ in mav.sent} == {"attitude_send"}
    assert replay.sent == {"ATTITUDE": 2}


def test_nothing_goes_out_before_the_recording_starts() -> None:
    replay = _attitudes([0.0, 0.5])
    assert replay.pump(_Mav(), {"ATTITUDE": 0.02}, 100.0, 1) == 0
