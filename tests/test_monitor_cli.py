"""`companion router` and `companion monitor` as separate processes on loopback."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.monitoring import MonitorConfig, MonitorPublisher
from tests.test_monitoring import free_port

ROOT = Path(__file__).resolve().parents[1]


def spawn(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "companion", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = spawn("router", "--listen", endpoint, "--seconds", "60")
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("router listening on")
    yield endpoint
    proc.terminate()
    assert proc.wait(timeout=10) == 143  # SIGTERM: a clean stop, status 128 + 15


def publish_for(pubs: list[MonitorPublisher], seconds: float) -> None:
    frame = np.zeros((60, 80, 3), np.uint8)
    frame[20:40, 30:50] = (0, 0, 255)
    jpeg = cv2.imencode(".jpg", frame)[1].tobytes()
    end = time.monotonic() + seconds
    n = 0
    while time.monotonic() < end:
        for pub in pubs:
            pub.publish_json("status", {"state": "tracking", "fps": 30.0, "n": n,
                                        "latency_ms": {"p50": 5.0, "p99": 9.0}})
            pub.publish_preview(jpeg)
        n += 1
        time.sleep(0.1)


def test_monitor_sees_two_vehicles_through_the_router(router: str) -> None:
    client = MonitorConfig(mode="client", connect=(router,))
    pubs = [MonitorPublisher(client, "alpha"), MonitorPublisher(client, "bravo")]
    monitor = spawn("monitor", "--connect", router, "--seconds", "3", "--json")
    try:
        publish_for(pubs, 4.0)
        out, err = monitor.communicate(timeout=30)
    finally:
        for pub in pubs:
            pub.close()
    assert monitor.returncode == 0, err
    seen = json.loads(out)["vehicles"]
    assert set(seen) == {"alpha", "bravo"}
    for vehicle in seen.values():
        assert vehicle["latest"]["status"]["state"] == "tracking"
        assert vehicle["counts"]["status"] >= 5
        assert vehicle["preview_bytes"] > 0
    assert "vehicle alpha: tracking" in err  # the text view


def test_monitor_snapshot_saves_the_preview_as_png(router: str, tmp_path: Path) -> None:
    pub = MonitorPublisher(MonitorConfig(mode="client", connect=(router,)), "alpha")
    out = tmp_path / "snap.png"
    monitor = spawn("monitor", "--connect", router, "--snapshot", str(out), "--seconds", "20")
    try:
        deadline = time.monotonic() + 20
        while monitor.poll() is None and time.monotonic() < deadline:
            publish_for([pub], 0.6)
        _, err = monitor.communicate(timeout=10)
    finally:
        pub.close()
    assert monitor.returncode == 0, err
    image = cv2.imread(str(out))
    assert image is not None and image.shape == (60, 80, 3)
    assert image[30, 40, 2] > 200 and image[5, 5, 2] < 50  # the red square came through
