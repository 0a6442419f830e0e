"""The dashboard in a real browser (Debian's chromium, headless, driven by Playwright).

A companion stand-in publishes on Zenoh; `companion dashboard` runs as its own process;
the page must show a preview that changes, counters equal to what was published, stale
data marked with its age, and refuse a wrong token with 401.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.monitoring import MonitorConfig, MonitorPublisher
from tests.test_monitoring import free_port

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync"]
OUT = ROOT / "test-output"


#: the status's per-stream report, as ``mavlink_bridge.streams.StreamWatch.report`` gives it
STREAMS = {"ATTITUDE": {"asked_hz": 30.0, "rate_hz": 29.6, "state": "arriving", "requests": 1},
           "DISTANCE_SENSOR": {"asked_hz": 20.0, "rate_hz": 0.0, "state": "missing",
                               "requests": 4}}


class FakeCompanion:
    """Publishes status, pose and a changing preview for one vehicle until stopped."""

    def __init__(self, endpoint: str, vehicle: str = "alpha") -> None:
        self.pub = MonitorPublisher(MonitorConfig(listen=(endpoint,), preview_rate_hz=2.0),
                                    vehicle, providers={"landmarks": self.landmarks})
        self.frames = 0
        self.running = True
        self.thread = threading.Thread(target=self.loop, daemon=True)

    @staticmethod
    def landmarks() -> list[dict[str, object]]:
        return [{"id": "sign-a", "position_ned_m": [20.0, 5.0, -2.0]},
                {"id": "poster-b", "position_ned_m": [15.0, -8.0, -3.0]}]

    def loop(self) -> None:
        while self.running:
            self.frames += 1
            img = np.zeros((120, 160, 3), np.uint8)
            cv2.putText(img, str(self.frames), (10, 80), cv2.FONT_HERSHEY_SIMPLEX, 2,
                        (255, 255, 255), 3)
            self.pub.publish_preview(cv2.imencode(".jpg", img)[1].tobytes())
            self.pub.publish_json("status", {
                "state": "tracking", "fps": 30.0, "latency_ms": {"p50": 6.0, "p99": 11.0},
                "link": "up", "dropped_frames": 0,
                "counters": {"frames": self.frames, "fixes_sent": self.frames - 1,
                             "fixes_accepted": self.frames - 2},
                "autopilot_streams": STREAMS})
            t = self.frames * 0.1
            self.pub.publish_json("pose", {
                "position_ned_m": [np.cos(t), np.sin(t), -5.0],
                "autopilot_position_ned_m": [np.cos(t) + 0.1, np.sin(t), -5.0],
                "landmark_ids": ["sign-a", "poster-b"], "quality": 90})
            time.sleep(0.1)

    def stop(self) -> None:
        self.running = False
        self.thread.join(timeout=5)
        self.pub.close()


def start_dashboard(endpoint: str, *extra: str) -> tuple[subprocess.Popen[str], str]:
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "companion", "dashboard", "--port", str(port),
         "--connect", endpoint, *extra],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            urllib.request.urlopen(url + "/", timeout=1)
            return proc, url
        except urllib.error.HTTPError:
            return proc, url  # it answers (e.g. 401): it is up
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise AssertionError(f"dashboard did not start: {proc.communicate()[1]}")


@pytest.fixture
def companion_and_dashboard() -> Iterator[tuple[FakeCompanion, str]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    fake = FakeCompanion(endpoint)
    fake.thread.start()
    other = FakeCompanion(f"tcp/127.0.0.1:{free_port()}", vehicle="bravo")
    other.pub.close()  # a second vehicle on the same network: it joins through the first
    other.pub = MonitorPublisher(MonitorConfig(connect=(endpoint,)), "bravo")
    other.thread.start()
    proc, url = start_dashboard(endpoint)
    yield fake, url
    proc.terminate()
    proc.wait(timeout=10)
    other.stop()
    fake.stop()


def test_page_shows_live_preview_and_the_published_counters(
    companion_and_dashboard: tuple[FakeCompanion, str],
) -> None:
    playwright = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip("chromium is not installed (apt-get install chromium)")
    fake, url = companion_and_dashboard
    OUT.mkdir(exist_ok=True)
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
        page = browser.new_page()
        page.goto(url + "/")
        page.wait_for_function("document.querySelector('#vehicle').options.length == 2",
                               timeout=15000)
        assert page.eval_on_selector_all("#vehicle option", "os => os.map(o => o.value)") \
            == ["alpha", "bravo"]
        page.select_option("#vehicle", "alpha")
        page.wait_for_function("document.querySelector('#preview').naturalWidth > 0",
                               timeout=15000)
        first = page.eval_on_selector("#preview", "e => e.src")
        page.wait_for_function(f"document.querySelector('#preview').src !== {first!r}",
                               timeout=10000)
        shot1 = page.locator("#preview").screenshot()
        time.sleep(1.2)
        shot2 = page.locator("#preview").screenshot()
        assert shot1 != shot2, "the preview did not change over time"
        # the three counters read in one script run: the page cannot update between them
        # (read one by one, an update between the reads gave (4, 3) in CI, 2026-11-29)
        cells = page.eval_on_selector_all(
            "td[data-key]", "cs => Object.fromEntries(cs.map(c => [c.dataset.key, c.innerText]))")
        shown, sent, accepted = (int(cells[k]) for k in ("frames", "fixes sent", "fixes accepted"))
        published = fake.frames
        # the page lags the publisher by < 1.5 s; 0 when it was read between the page's
        # update and the publisher's next frame (10 a second): seen once in CI, 2026-11-29
        assert 0 <= published - shown <= 15
        assert (sent - shown, accepted - shown) == (-1, -2)  # exactly the published relation
        assert page.inner_text("td[data-key='state']") == "tracking"
        # each stream: its state, the rate it arrives at and the rate asked (issue 19)
        assert (cells["stream ATTITUDE"], cells["stream DISTANCE_SENSOR"]) \
            == ("arriving 29.6 / 30 Hz", "missing 0.0 / 20 Hz"), cells
        assert not page.is_visible("#stale")
        page.wait_for_function("document.querySelector('#plot') !== null")
        page.screenshot(path=str(OUT / "dashboard.png"), full_page=True)
        fake.running = False  # the companion goes silent: the page must say so
        page.wait_for_selector("#stale", state="visible", timeout=10000)
        assert page.inner_text("#stale").startswith("STALE: no status for")
        browser.close()


def test_wrong_token_is_refused_with_401_and_nothing_leaks() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc, url = start_dashboard(endpoint, "--token", "s3cret")
    try:
        for path in ("/", "/api/fleet", "/api/preview/alpha", "/api/fleet?token=wrong"):
            with pytest.raises(urllib.error.HTTPError) as info:
                urllib.request.urlopen(url + path, timeout=5)
            assert info.value.code == 401
            assert info.value.read() == b"unauthorized"
        ok = urllib.request.urlopen(url + "/api/fleet?token=s3cret", timeout=5)
        assert ok.status == 200
        req = urllib.request.Request(url + "/api/fleet",
                                     headers={"Authorization": "Bearer s3cret"})
        assert urllib.request.urlopen(req, timeout=5).status == 200
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_binding_beyond_loopback_without_a_token_is_refused() -> None:
    out = subprocess.run([sys.executable, "-m", "companion", "dashboard", "--host", "0.0.0.0"],
                         cwd=ROOT, capture_output=True, text=True, timeout=30, check=False)
    assert out.returncode == 2
    assert out.stderr.strip() == ("dashboard: binding to 0.0.0.0 needs --token (or "
                                  "LMC_DASHBOARD_TOKEN): the page must not be open to the network")


def test_page_against_a_running_demo(tmp_path: Path) -> None:
    """The real thing: `companion demo` publishes, the page shows its preview and numbers."""
    playwright = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip("chromium is not installed (apt-get install chromium)")
    from companion.monitoring import MonitorWatcher

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    demo = subprocess.Popen(
        [sys.executable, "-m", "companion", "--log-level", "warning",
         "--set", f'monitor.listen=["{endpoint}"]',
         "--set", f'flightlog.dir="{tmp_path}"', "demo", "--seconds", "25", "--json"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc, url = start_dashboard(endpoint)
    watcher = MonitorWatcher(MonitorConfig(connect=(endpoint,)))
    OUT.mkdir(exist_ok=True)
    try:
        assert watcher.wait_for("preview", timeout_s=30)
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
            page = browser.new_page()
            page.goto(url + "/")
            page.wait_for_function("document.querySelector('#preview').naturalWidth > 0",
                                   timeout=20000)
            shot1 = page.locator("#preview").screenshot()
            time.sleep(1.5)
            shot2 = page.locator("#preview").screenshot()
            assert shot1 != shot2, "the demo's preview did not change over time"
            page.wait_for_function(
                "document.querySelector(\"td[data-key='fixes sent']\") !== null", timeout=20000)
            shown = int(page.inner_text("td[data-key='fixes sent']"))
            published = watcher.snapshot().vehicles["lmc1"].latest["status"]["counters"]
            # the page polls every 0.5 s and the status comes at 1 Hz: within two periods
            assert abs(published["fixes_sent"] - shown) <= 2 * 30
            assert page.inner_text("td[data-key='state']") in ("tracking", "searching", "lost")
            page.screenshot(path=str(OUT / "dashboard-demo.png"), full_page=True)
            browser.close()
    finally:
        watcher.close()
        proc.terminate()
        proc.wait(timeout=10)
        demo.terminate()
        demo.wait(timeout=30)
