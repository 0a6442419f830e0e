"""The stream watch on a clock of its own: a stream that stops mid-flight, without a reboot,
is asked for again with back-off, reported missing once, and arriving again once it does
(issue 19: "ask again when one stops")."""

from __future__ import annotations

import logging

import pytest

from mavlink_bridge.streams import StreamSpec, StreamWatch

S = 1_000_000_000  # ns


class Autopilot:
    """What the watch talks to: the requests and STATUSTEXTs it sent."""

    def __init__(self) -> None:
        self.requests: list[tuple[float, str, int]] = []
        self.texts: list[str] = []
        self.now_ns = 0

    def request(self, name: str, interval_us: int) -> None:
        self.requests.append((self.now_ns / S, name, interval_us))

    def statustext(self, text: str, _severity: int) -> None:
        self.texts.append(text)


def run(watch: StreamWatch, ap: Autopilot, until_s: float, sending: bool,
        hz: float = 30.0) -> None:
    """Advance to ``until_s`` in 10 ms ticks, ATTITUDE arriving at ``hz`` while ``sending``."""
    period_ns, next_ns = round(S / hz), ap.now_ns
    while ap.now_ns < until_s * S:
        ap.now_ns += 10_000_000
        if sending and ap.now_ns >= next_ns:
            watch.on_message("ATTITUDE", ap.now_ns)
            next_ns += period_ns
        watch.tick(ap.now_ns)


def test_a_stream_that_stops_mid_flight_is_asked_for_again_and_comes_back(
        caplog: pytest.LogCaptureFixture) -> None:
    ap = Autopilot()
    watch = StreamWatch([StreamSpec("ATTITUDE", 30.0)], ap.request, ap.statustext)
    watch.ask_all(0)
    run(watch, ap, 5.0, sending=True)
    assert watch.report(ap.now_ns)["ATTITUDE"]["state"] == "arriving"
    assert len(ap.requests) == 1 and ap.texts == []

    caplog.set_level(logging.INFO, logger="mavlink_bridge.streams")
    run(watch, ap, 12.0, sending=False)  # stops at 5 s, no reboot
    report = watch.report(ap.now_ns)["ATTITUDE"]
    assert report["state"] == "missing" and report["rate_hz"] == 0.0
    assert ap.texts == ["ATTITUDE missing (asked 30 Hz)"]  # one episode, one STATUSTEXT
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "ATTITUDE missing" in warnings[0].getMessage()
    again = [t for t, name, us in ap.requests[1:] if name == "ATTITUDE" and us == 33333]
    # silent for five periods (0.5 s at least) -> missing at ~5.5 s and asked at once (the
    # last request was long ago), then 1 and 2 s later (the back-off doubling, up to 8 s)
    assert [round(t, 1) for t in again] == [5.5, 6.5, 8.5]

    run(watch, ap, 16.0, sending=True)
    assert watch.report(ap.now_ns)["ATTITUDE"]["state"] == "arriving"
    assert ap.texts == ["ATTITUDE missing (asked 30 Hz)", "ATTITUDE arriving"]
    assert len(ap.requests) == 4  # nothing more asked once it arrives
    assert watch.missing() == []


def test_a_stream_arriving_at_a_third_of_its_rate_is_slow_once() -> None:
    ap = Autopilot()
    watch = StreamWatch([StreamSpec("ATTITUDE", 30.0)], ap.request, ap.statustext)
    watch.ask_all(0)
    run(watch, ap, 6.0, sending=True, hz=10.0)
    report = watch.report(ap.now_ns)["ATTITUDE"]
    assert report["state"] == "slow" and 9.0 <= float(report["rate_hz"]) <= 11.0
    assert len(ap.texts) == 1 and ap.texts[0].startswith("ATTITUDE slow: ")
    assert watch.missing() == ["ATTITUDE"] and len(ap.requests) == 1  # slow: not re-asked
