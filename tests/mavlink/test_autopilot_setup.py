"""``companion autopilot setup`` against the fake autopilot, which starts with the real
autopilot's parameter defaults and answers the parameter protocol."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from companion.cli import main
from companion.cli.autopilot_cmd import DELAY_MARGIN_MS, delay_from
from companion.flightlog import FORMAT, VERSION
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig
from mavlink_bridge.params import autopilot_defaults, profile_parameters, same_value
from tests.follow.test_run_follow import fake_in_thread


def setup_args(port: int, profile: str, *extra: str) -> list[str]:
    return ["--set", "monitor.enabled=false", "autopilot", "setup", "--profile", profile,
            "--endpoint", f"udpout:127.0.0.1:{port}", "--timeout", "5", *extra]


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_setup_sets_reads_back_and_says_reboot(profile: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Defaults -> wanted with --yes; read back; the second run has nothing to set.  PX4's
    INT32 parameters travel byte-wise: a wrong encoding would read back wrong."""
    wanted = profile_parameters(profile, 45.0)
    with fake_in_thread(FakeAutopilotConfig(profile=profile)) as fake:  # type: ignore[arg-type]
        assert fake.params.values == autopilot_defaults(profile)
        status = main(setup_args(fake.local_port, profile, "--yes", "--delay-ms", "45"))
        out = capsys.readouterr().out
        values = dict(fake.params.values)
        # the estimator reads the noise floor and the delay at every fix, as the real ones do
        live = (fake.ekf.noise_floor_m, fake.ekf.delay_ms)
        again = main(setup_args(fake.local_port, profile, "--delay-ms", "45",
                                "--streams-s", "0"))
        out2 = capsys.readouterr().out
        fake.reboot(0.0)  # stored parameters outlive a reboot
        rebooted = (fake.ekf.noise_floor_m, fake.ekf.delay_ms)
    assert status == 0, out
    noise = "VISO_POS_M_NSE" if profile == "ardupilot" else "EKF2_EVP_NOISE"
    assert live == rebooted == pytest.approx((wanted[noise], 45.0)), (live, rebooted)
    assert all(same_value(values[k], v) for k, v in wanted.items()), values
    delay = "VISO_DELAY_MS" if profile == "ardupilot" else "EKF2_EV_DELAY"
    assert values[delay] == 45.0
    if profile == "ardupilot":
        assert "reboot the autopilot: VISO_TYPE, GPS1_TYPE" in out, out
    else:  # PX4's EKF2_HGT_REF: @reboot_required true
        assert "reboot the autopilot: EKF2_HGT_REF" in out, out
    assert again == 0 and "nothing to set" in out2, out2
    # the streams the companion will ask for: asked the same way, seen arriving
    assert "no stream-rate parameter is needed" in out, out
    assert re.search(r"ATTITUDE +asked \d+ Hz: arriving at [1-9]", out), out
    assert "MISSING" not in out, out
    # no EKF origin yet (none set here): no local position, said so, not an error
    assert re.search(r"LOCAL_POSITION_NED +asked 10 Hz: none yet", out), out
    assert "streams" not in out2


def test_setup_says_which_needed_stream_does_not_arrive(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A range finder configured, none on the autopilot: DISTANCE_SENSOR is asked for and never
    comes; the parameters are fine, the exit status is not."""
    with fake_in_thread(FakeAutopilotConfig(absent=("DISTANCE_SENSOR",))) as fake:
        first = main(setup_args(fake.local_port, "ardupilot", "--yes", "--streams-s", "0"))
        status = main(["--set", "pose.rangefinder=true",
                       *setup_args(fake.local_port, "ardupilot", "--streams-s", "3")])
    captured = capsys.readouterr()
    assert first == 0, captured.out
    assert status == 1
    assert re.search(r"DISTANCE_SENSOR +asked 20 Hz: MISSING", captured.out), captured.out
    assert re.search(r"ATTITUDE +asked \d+ Hz: arriving", captured.out), captured.out
    last = captured.err.strip().splitlines()[-1]
    assert last.startswith("autopilot setup: not arriving as asked: DISTANCE_SENSOR"), last


def test_setup_without_yes_and_no_answer_sets_nothing(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("builtins.input", lambda _prompt: "n")
    with fake_in_thread(FakeAutopilotConfig()) as fake:
        status = main(setup_args(fake.local_port, "ardupilot", "--streams-s", "0"))
        values, sets = dict(fake.params.values), list(fake.params.sets)
    out = capsys.readouterr().out
    assert status == 1 and "nothing set" in out
    assert sets == [] and values == autopilot_defaults("ardupilot")
    assert "VISO_TYPE" in out and "-> 1" in out  # the table showed current -> wanted


def test_a_bad_streams_time_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["autopilot", "setup", "--endpoint", "udpout:127.0.0.1:9",
                   "--streams-s", "-1"])
    err = capsys.readouterr().err
    assert status != 0 and "Traceback" not in err
    assert err.strip().splitlines()[-1].endswith("--streams-s: expected 0..60 (0: skip), got -1")


def test_streams_watched_too_briefly_are_not_called_arriving(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Under the 2 Hz stream's missing time, a stream not heard yet is said to be unknown,
    not "arriving at 0 Hz"."""
    with fake_in_thread(FakeAutopilotConfig()) as fake:
        main(setup_args(fake.local_port, "ardupilot", "--yes", "--streams-s", "0.3"))
    out = capsys.readouterr().out
    assert "arriving at 0 Hz" not in out, out
    assert re.search(r"EKF_STATUS_REPORT +asked 2 Hz: (nothing yet|heard) \(watched too "
                     r"briefly", out), out


def test_setup_without_an_autopilot_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["autopilot", "setup", "--endpoint", "udpout:127.0.0.1:9", "--timeout",
                   "0.5"])
    err = capsys.readouterr().err
    assert status != 0 and "no autopilot heartbeat" in err and "Traceback" not in err


def test_the_delay_from_a_flight_log_is_ardupilots_least_latency(tmp_path: Path) -> None:
    """ArduPilot's jitter correction places each fix by the quickest fix's lag, so its
    VISO_DELAY_MS is the least capture-to-wire latency while the p50 is inside EKF3's 60 ms
    fusion horizon, and the p50 beyond it (EKF3 then takes each fix at its arrival less
    VISO_DELAY_MS); PX4 keeps p50 plus the margin, and a log written before the least was
    recorded gives p50 plus the margin for both."""
    log = tmp_path / "flight.jsonl"
    latency = {"min": 12.4, "p50": 40.0, "p99": 90.0}
    status = {"kind": "status", "latency_ms": latency}
    log.write_text("\n".join(json.dumps(r) for r in (
        {"format": FORMAT, "version": VERSION, "kind": "header"}, status)) + "\n")
    args = argparse.Namespace(delay_ms=None, flightlog=log)
    assert delay_from(args, "ardupilot")[0] == pytest.approx(12.4)
    assert delay_from(args, "px4")[0] == pytest.approx(40.0 + DELAY_MARGIN_MS)
    latency.update({"min": 68.0, "p50": 133.0})  # a slow machine (docs/sitl.md)
    log.write_text("\n".join(json.dumps(r) for r in (
        {"format": FORMAT, "version": VERSION, "kind": "header"}, status)) + "\n")
    assert delay_from(args, "ardupilot")[0] == pytest.approx(133.0)
    latency["p50"] = 40.0
    del latency["min"]
    log.write_text("\n".join(json.dumps(r) for r in (
        {"format": FORMAT, "version": VERSION, "kind": "header"}, status)) + "\n")
    assert delay_from(args, "ardupilot")[0] == pytest.approx(40.0 + DELAY_MARGIN_MS)
