"""config/vehicle-example.toml flies: ``companion run`` with it, overriding only the link
(the fake autopilot on loopback) and the source (a recording written by ``companion
synth``), sends fixes the autopilot accepts (issue 24)."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.cli import main
from companion.settings import load_settings
from tests.run_helpers import fake_flying, flight_records, synth

EXAMPLE = Path(__file__).resolve().parents[1] / "config" / "vehicle-example.toml"


def test_the_example_is_a_real_vehicle() -> None:
    s = load_settings([EXAMPLE])
    assert s.mavlink.endpoint.startswith("serial:/dev/")
    assert (s.source.kind, s.source.spec) == ("camera", "/dev/video0")
    assert s.landmarks.map_path == ""  # the landmark database
    assert (s.mavlink.origin_lat_deg, s.mavlink.origin_lon_deg) != (0.0, 0.0)


def test_run_with_the_example_sends_fixes_the_autopilot_accepts(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Fails before issue 24: there was no example, run ignored the landmark database and
    sent no fix from a recording (every fix "stale")."""
    hover = synth(tmp_path / "recording", seconds=6.0, scenario="hover")
    monkeypatch.chdir(tmp_path)  # the unit's WorkingDirectory: landmarks.sqlite, flightlogs/
    assert main(["landmarks", "--config", str(EXAMPLE), "import",
                 str(hover / "landmarks.geojson")]) == 0
    with fake_flying("hover") as fake:
        status = main(["run", "--config", str(EXAMPLE),
                       "--set", f'mavlink.endpoint="udpout:127.0.0.1:{fake.local_port}"',
                       "--set", f'source.spec="stream:{hover}"', "--set", "source.kind=auto"])
        accepted = len(fake.accepted())
    err = capsys.readouterr().err
    assert status == 0, err
    assert "flying with 6 landmarks from the practical map of" in err, err
    status_records = [r for r in flight_records(tmp_path / "flightlogs")
                      if r["kind"] == "status"]
    sent = status_records[-1]["counters"]["fixes_sent"]
    assert sent >= 10, status_records[-1]  # 0 before; ~100 seen, fewer under load
    assert accepted > 0.8 * sent, (accepted, sent)
