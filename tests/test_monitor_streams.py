"""The monitor shows the autopilot streams and the health warnings of the status."""

from __future__ import annotations

import time

from companion.monitoring.render import render_vehicle
from companion.monitoring.watcher import VehicleView


def test_streams_and_warnings_are_shown() -> None:
    status = {"state": "tracking", "autopilot_streams": {
        "ATTITUDE": {"asked_hz": 30.0, "rate_hz": 29.5, "state": "arriving", "requests": 1},
        "DISTANCE_SENSOR": {"asked_hz": 20.0, "rate_hz": 0.0, "state": "missing",
                            "requests": 4}},
        "warnings": ["autopilot stream DISTANCE_SENSOR not arriving"]}
    view = VehicleView("lmc1", {"status": status}, {"status": time.monotonic()},
                       {"status": 1}, (), None)
    text = "\n".join(render_vehicle(view))
    assert "ATTITUDE arriving 29.5/30 Hz" in text
    assert "DISTANCE_SENSOR missing 0.0/20 Hz" in text
    assert "WARNING autopilot stream DISTANCE_SENSOR not arriving" in text
