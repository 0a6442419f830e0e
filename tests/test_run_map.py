"""``companion run`` flies the landmark database's practical map (or ``map_path`` when set),
says which landmarks can be acquired and why the others cannot, and names the reason
when no fix can come (issue 24)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.cli import main
from tests.run_helpers import flight_records, free_udp_port, run_args, synth, write_subset
from tests.test_monitor_cli import spawn
from tests.test_monitoring import free_port


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synth(tmp_path_factory.mktemp("stream") / "survey", seconds=2.0)


def import_db(tmp_path: Path, map_file: Path) -> Path:
    db = tmp_path / "board.sqlite"
    assert main(["landmarks", "--db", str(db), "import", str(map_file)]) == 0
    return db


def test_run_flies_the_databases_practical_map_and_says_why_others_cannot_be_acquired(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Fails before issue 24: run read only map_path (the sample street, 6 landmarks)."""
    subset = write_subset(stream, tmp_path / "mine.geojson", {
        "wall-01": {}, "sign-01": {"appearance": None},
        "wall-02": {"status": "candidate"}})
    db = import_db(tmp_path, subset)
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "1",
                           "--set", f'landmarks.db_path="{db}"',
                           "--set", "landmarks.min_spacing_m=1"))  # the street's are 6 m apart
    err = capsys.readouterr().err
    assert status == 0, err
    assert f"flying with 2 landmarks from the practical map of {db}" in err, err
    assert "landmark sign-01 cannot be acquired: no appearance image" in err, err
    assert "landmark wall-02 not in the practical map: status candidate" in err, err
    records = flight_records(tmp_path / "logs")
    event = next(r for r in records if r.get("event") == "map")
    assert sorted(event["loaded"]) == ["sign-01", "wall-01"]
    assert event["with_reference"] == ["wall-01"]
    assert list(event["cannot_acquire"]) == ["sign-01"]
    status_map = next(r for r in records if r["kind"] == "status")["map"]
    assert (status_map["loaded"], status_map["with_reference"]) == (2, 1)


def test_an_explicit_map_path_is_flown_instead_of_the_database(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = import_db(tmp_path, write_subset(stream, tmp_path / "db.geojson", {"wall-01": {}}))
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "0.5",
                           "--set", f'landmarks.db_path="{db}"',
                           "--set", f'landmarks.map_path="{stream / "landmarks.geojson"}"'))
    err = capsys.readouterr().err
    assert status == 0, err
    assert f"flying with 6 landmarks from the map file {stream / 'landmarks.geojson'}" in err


def blocked_causes(tmp_path: Path) -> list[tuple[int, str]]:
    """(t_us, cause) of every status that says ``blocked``."""
    return [(r["t_us"], r["no_fix_cause"]["cause"]) for r in flight_records(tmp_path / "logs")
            if r["kind"] == "status" and r["state"] == "blocked"]


def test_no_references_is_named_in_the_status_log_and_events_at_once(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Fails before issue 24: the state stayed "searching" and nothing said why."""
    subset = write_subset(stream, tmp_path / "plain.geojson",
                          {"wall-01": {"appearance": None}, "wall-02": {"appearance": None}})
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "1",
                           "--set", f'landmarks.map_path="{subset}"'))
    err = capsys.readouterr().err
    assert status == 0, err
    assert "no fix can come: no-references: none of the 2 landmarks" in err, err
    records = flight_records(tmp_path / "logs")
    start = records[0]["t_us"] if "t_us" in records[0] else records[1]["t_us"]
    causes = blocked_causes(tmp_path)
    assert causes and all(c == "no-references" for _, c in causes)
    assert causes[0][0] - start < 2_000_000  # named at once, not after a timeout
    assert any(r.get("event") == "no-fix" and r["cause"] == "no-references" for r in records)


def test_a_link_that_never_comes_up_is_named_within_seconds(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Fails before issue 24: "link-down" (or "starting") only, never why no fix comes."""
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "5",
                           "--set", f'landmarks.map_path="{stream / "landmarks.geojson"}"',
                           "--set", "source.loop=true"))
    err = capsys.readouterr().err
    assert status == 0, err
    assert "no fix can come: link-never-up: no HEARTBEAT from the autopilot on udpout:" in err
    assert err.count("no fix can come:") == 1, err  # once per cause, not per evaluation
    assert "link-never-up" in {c for _, c in blocked_causes(tmp_path)}


def test_an_origin_far_from_every_landmark_is_named(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Fails before issue 24: an origin 16,000 km away started without a word."""
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "0.5",
                           "--set", f'landmarks.map_path="{stream / "landmarks.geojson"}"',
                           "--set", "mavlink.origin_lat_deg=-33.0",
                           "--set", "mavlink.origin_lon_deg=151.0"))
    err = capsys.readouterr().err
    assert status == 0, err
    assert "no fix can come: origin-far: the EKF origin is 16" in err, err
    assert {c for _, c in blocked_causes(tmp_path)} == {"origin-far"}


def test_an_origin_far_from_the_databases_landmarks_is_named(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = import_db(tmp_path, stream / "landmarks.geojson")
    capsys.readouterr()
    main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "0.5",
                  "--set", f'landmarks.db_path="{db}"', "--set", "mavlink.origin_lat_deg=47.5"))
    err = capsys.readouterr().err
    assert "flying with 0 landmarks" in err
    assert "no fix can come: origin-far: the EKF origin is 13.7 km from the nearest " \
           "landmark" in err, err


def test_a_missing_database_is_one_line(tmp_path: Path, stream: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    status = main(run_args(tmp_path, stream, free_udp_port(), "--seconds", "0.5",
                           "--set", f'landmarks.db_path="{tmp_path / "typo.sqlite"}"'))
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert err[-1].endswith("landmarks.db_path: no such database (import landmarks with "
                            "`companion landmarks import`, or set landmarks.map_path to a "
                            "GeoJSON map)"), err
    assert not (tmp_path / "typo.sqlite").exists()


def test_the_cause_is_on_zenoh_for_a_monitor_in_another_process(
        tmp_path: Path, stream: Path) -> None:
    """The status and the events a monitor receives name the cause (issue 24)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    subset = write_subset(stream, tmp_path / "plain.geojson", {"wall-01": {"appearance": None}})
    monitor = spawn("monitor", "--connect", endpoint, "--seconds", "8", "--json",
                    "--vehicle", "d1blocked")
    run = spawn(*run_args(tmp_path, stream, free_udp_port(), "--seconds", "6",
                          "--set", f'landmarks.map_path="{subset}"',
                          "--set", "monitor.enabled=true", "--set", "vehicle.id=d1blocked",
                          "--set", f'monitor.listen=["{endpoint}"]', "--set", "source.loop=true"))
    try:
        out, err = monitor.communicate(timeout=60)
        run.communicate(timeout=60)
    finally:
        for proc in (run, monitor):
            proc.kill()
            proc.wait(timeout=10)
    assert monitor.returncode == 0, err
    seen = json.loads(out)["vehicles"]["d1blocked"]
    status = seen["latest"]["status"]
    assert status["state"] == "blocked", status
    assert status["no_fix_cause"]["cause"] == "no-references"
    assert status["map"]["cannot_acquire"] == {"wall-01": "no appearance image: nothing to "
                                               "look for (add one to the map)"}
    assert "no fix can come: no-references: none of the 1 landmarks" in err  # the text view
