"""A ``companion run`` configuration for a simulated flight against the fake autopilot,
shared by the scenario tests (sitl_tests) and the soak (testsupport.soak)."""

from __future__ import annotations

from pathlib import Path

from companion.sim.scenario import load_scenario


def run_config(tmp: Path, port: int, *, scenario: str = "hover",
               map_path: Path | None = None, extra: str = "",
               name: str = "flight.toml") -> Path:
    """A ``--config`` file for ``companion run``: a simulated scenario, the fake autopilot on
    ``port``, the flight log under ``tmp/logs``; ``extra`` is appended TOML."""
    o = load_scenario(scenario).origin
    root = Path(__file__).resolve().parents[1]  # the repository
    map_path = map_path or root / "config" / "landmarks.geojson"
    path = tmp / name
    path.write_text(f"""
[source]
kind = "sim"
spec = "{Path(scenario).as_posix() if scenario.endswith('.toml') else scenario}"
[mavlink]
endpoint = "udpout:127.0.0.1:{port}"
origin_lat_deg = {o.lat}
origin_lon_deg = {o.lon}
origin_alt_m = {o.alt_m}
[landmarks]
map_path = "{Path(map_path).as_posix()}"
[flightlog]
dir = "{(tmp / 'logs').as_posix()}"
{extra}
""", encoding="utf-8")
    return path
