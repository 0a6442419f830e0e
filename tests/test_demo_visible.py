"""``companion demo`` is seen by ``companion monitor`` and ``companion dashboard`` started
with no options in another process, as the README says (issue 24)."""

from __future__ import annotations

import json
import time
import urllib.request

from tests.test_monitor_cli import spawn
from tests.test_monitoring import free_port


def test_a_demo_is_seen_by_a_monitor_and_a_dashboard_started_without_options() -> None:
    """Fails before issue 24: the demo listened on no fixed endpoint and both saw nothing."""
    port = free_port()
    dashboard = spawn("dashboard", "--port", str(port))
    monitor = spawn("monitor", "--seconds", "14", "--json", "--vehicle", "d1seen")
    time.sleep(1.0)
    demo = spawn("demo", "--seconds", "10", "--set", "vehicle.id=d1seen")
    try:
        seen, err = monitor.communicate(timeout=90)
        fleet = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/api/fleet",
                                                  timeout=10).read())
        _, demo_err = demo.communicate(timeout=90)
    finally:
        for proc in (demo, monitor, dashboard):
            proc.terminate()
            proc.wait(timeout=20)
    assert monitor.returncode == 0, err
    assert "monitoring on Zenoh: listening on tcp/127.0.0.1:7447" in demo_err \
        or "connected to tcp/127.0.0.1:7447" in demo_err, demo_err
    vehicles = json.loads(seen)["vehicles"]
    assert "d1seen" in vehicles, seen[:500]
    assert vehicles["d1seen"]["counts"].get("status", 0) >= 3
    assert "d1seen" in json.dumps(fleet), str(fleet)[:500]
