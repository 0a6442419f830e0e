"""`companion demo` as a user runs it, and a fleet of demos seen through a router.

These run real flights (a few seconds each, in real time): the simulated camera, the fake
autopilot on UDP loopback, the MAVLink bridge and Zenoh.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from companion import demo
from companion.cli import main as cli_main
from mavlink_bridge.fake_drift import AttitudeErrorConfig
from tests.test_monitor_cli import spawn
from tests.test_monitoring import free_port

ROOT = Path(__file__).resolve().parents[1]
KEYS = {"frames", "fps", "fixes_sent", "fixes_accepted", "position_rmse_m",
        "mean_landmark_distance_m", "latency_p50_ms", "latency_p99_ms", "dropped_frames",
        "cpu_cores_busy"}


def test_demo_json_reports_a_flight_the_autopilot_fused(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "companion", "--log-level", "warning",
         "--set", f"flightlog.dir={json.dumps(str(tmp_path))}",
         "demo", "--seconds", "8", "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert KEYS <= set(summary)
    # every one of the 240 frames (8 s at 30 fps) is either processed or counted as dropped:
    # how many get processed depends on the machine, that none vanishes does not
    assert summary["frames"] + summary["dropped_frames"] in range(236, 242)
    assert summary["frames"] > 0
    assert summary["fixes_sent"] > 0
    assert summary["fixes_accepted"] >= 0.9 * summary["fixes_sent"]
    # against the simulated truth: ~0.3 % of the distance with sub-pixel corners (0.75 %
    # before the alignment's half-pixel and edge-smoothing biases were removed)
    assert summary["position_rmse_m"] < 0.006 * summary["mean_landmark_distance_m"]
    assert 0.0 < summary["cpu_cores_busy"] < 2.0
    logs = list(tmp_path.glob("demo-*.jsonl"))
    assert len(logs) == 1
    kinds = {json.loads(line)["kind"] for line in logs[0].read_text().splitlines()}
    assert {"header", "fix", "track", "event", "status"} <= kinds


def test_two_demos_and_a_monitor_meet_through_a_router(tmp_path: Path) -> None:
    """A fleet: two companions (distinct ids), a router and a monitor, each its own process."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = spawn("router", "--listen", endpoint, "--seconds", "90")
    assert router.stdout is not None and router.stdout.readline().startswith("router")
    demos = [
        spawn("--log-level", "warning", "--set", f"vehicle.id={vid}",
              "--set", f'monitor.connect=["{endpoint}"]',
              "--set", f"flightlog.dir={json.dumps(str(tmp_path / vid))}",
              "demo", "--seconds", "10", "--json")
        for vid in ("alpha", "bravo")
    ]
    monitor = spawn("monitor", "--connect", endpoint, "--seconds", "9", "--json")
    try:
        seen, err = monitor.communicate(timeout=60)
        results = [d.communicate(timeout=90) for d in demos]
    finally:
        for proc in (*demos, monitor, router):
            proc.kill() if proc.poll() is None else None
        router.wait(timeout=10)
    assert monitor.returncode == 0, err
    vehicles = json.loads(seen)["vehicles"]
    assert set(vehicles) == {"alpha", "bravo"}
    for vid in ("alpha", "bravo"):
        assert vehicles[vid]["counts"]["status"] >= 3
        assert vehicles[vid]["latest"]["status"]["vehicle"] == vid
        assert vehicles[vid]["counts"].get("tracks", 0) > 10
    for (out, err_d), proc in zip(results, demos, strict=True):
        assert proc.returncode == 0, err_d
        assert json.loads(out)["fixes_sent"] > 0


def test_sigterm_mid_flight_is_a_clean_stop_with_the_log_complete(tmp_path: Path) -> None:
    """SIGTERM: finish the frame in hand, final STATUSTEXT, flush the log, exit 143."""
    import signal
    import time

    proc = spawn("--log-level", "info", "--set", f"flightlog.dir={json.dumps(str(tmp_path))}",
                 "demo", "--seconds", "60", "--json")
    assert proc.stderr is not None
    deadline = time.monotonic() + 60
    for line in proc.stderr:  # wait until the flight is really under way
        if "health searching -> " in line or "-> tracking" in line:
            break
        assert time.monotonic() < deadline, "the demo never started tracking"
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 143  # a clean stop asked by SIGTERM: 128 + 15 (issue 24)
    summary = json.loads(out)
    assert summary["frames"] > 0
    records = [json.loads(line) for line in next(tmp_path.glob("demo-*.jsonl")).read_text()
               .splitlines()]
    assert records[-1]["kind"] == "status"  # the final status is the last line
    assert any(r["kind"] == "event" and r.get("event") == "stopped" for r in records[-3:])
    assert records[-1]["counters"]["frames"] == summary["frames"]  # nothing processed unlogged


def test_a_missing_detector_model_is_one_line_and_nothing_is_left_running() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "companion", "--set", "perception.use_detector=true",
         "--set", "detector.model_path=/no/such/model.onnx", "demo", "--seconds", "5"],
        cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1] == "/no/such/model.onnx: model file not found"



class _CapturedError(Exception):
    """Stops the demo as soon as its fake autopilot is configured."""


def _fake_config_of(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> Any:
    """The FakeAutopilotConfig `companion demo ARGV` gives its fake autopilot."""
    seen: list[Any] = []

    def capture(config: Any, *_args: Any, **_kw: Any) -> None:
        seen.append(config)
        raise _CapturedError

    monkeypatch.setattr(demo, "AutopilotProcess", capture)  # the fake's own process
    with pytest.raises(_CapturedError):
        cli_main(["--log-level", "warning", "demo", "--seconds", "1", *argv])
    return seen[0]


def test_attitude_error_flag_makes_the_fake_autopilot_drift(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """`--attitude-error` hands the fake autopilot a real EKF's error (the fake's default
    ``AttitudeErrorConfig``); without it the demo's attitude is exact."""
    assert _fake_config_of([], monkeypatch).attitude_error is None
    drift = _fake_config_of(["--attitude-error"], monkeypatch).attitude_error
    assert drift == AttitudeErrorConfig() and drift.yaw_sigma_deg >= 3.0
