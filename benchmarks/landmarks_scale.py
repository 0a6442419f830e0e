"""Scale benchmark of the landmark database (issue 5): prints numbers, asserts nothing.

* import rate: a GeoJSON map of ``--geojson-count`` features through ``import_map``
  (read + validate + one transaction), and ``--count`` records through
  ``import_landmarks`` (SQLite; PostGIS with COPY);
* area selection: ``--repeats`` random ``--area-km`` squares inside the populated region,
  ``select_area`` = index query + exact filter + greedy practical-map selection; median,
  p90 and the mean number of landmarks per area.

Landmarks are spread uniformly over a ``--region-km`` square (default 40 km: 1,000,000
landmarks give ~625 per km^2, ~2,500 per 2 km x 2 km area).  PostGIS runs in a throwaway
cluster (testsupport/pgcluster.py); it is skipped with the reason if not installed.

    PYTHONPATH=. python benchmarks/landmarks_scale.py [--count 1000000] [--backend sqlite]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from companion.core.landmark import BBox, Category, Landmark, Scores
from companion.core.map_file import landmark_to_feature
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.repository import LandmarkRepository, import_map
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository
from companion.landmarks.sync import select_area

ORIGIN = (48.8566, 2.3522)
CATEGORIES: tuple[Category, ...] = ("signpost", "wall_image", "logo", "other")


def make_landmarks(n: int, region_km: float, rng: np.random.Generator) -> list[Landmark]:
    half = region_km * 500.0
    north, east = rng.uniform(-half, half, n), rng.uniform(-half, half, n)
    lat, lon, _ = pymap3d.ned2geodetic(north, east, 0.0, *ORIGIN, 0.0)
    impact = rng.uniform(0.0, 1.0, n)
    facing = rng.uniform(0.0, 360.0, n)
    return [
        Landmark(f"lm{k:07d}", f"landmark {k}", CATEGORIES[k % 4], float(a), float(o), 35.0,
                 1.5, 1.0, float(f), "approved", "", Scores(0.8, 0.9, 0.9, float(s)))
        for k, (a, o, f, s) in enumerate(zip(lat.tolist(), lon.tolist(), facing.tolist(),
                                             impact.tolist(), strict=True))
    ]


def timed(fn: Callable[[], object]) -> float:
    """Wall-clock seconds of one call."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def timed_cpu(fn: Callable[[], object]) -> tuple[float, float]:
    """(wall, this process's CPU) seconds of one call: the machine may be shared."""
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def load() -> str:
    return "load average " + " ".join(f"{x:.1f}" for x in os.getloadavg())


def bench_geojson_import(make_repo: Callable[[], LandmarkRepository], records: list[Landmark],
                         tmp: Path, label: str) -> None:
    path = tmp / "map.geojson"
    with path.open("w") as out:
        json.dump({"type": "FeatureCollection",
                   "features": [landmark_to_feature(lm, None) for lm in records]}, out)
    repo = make_repo()
    try:
        dt, cpu = timed_cpu(lambda: import_map(repo, path))
    finally:
        repo.close()
    print(f"{label}: GeoJSON import of {len(records):,} features "
          f"({path.stat().st_size / 1e6:.0f} MB): {dt:.2f} s = {len(records) / dt:,.0f} records/s "
          f"(client CPU {cpu:.2f} s; {load()})")


def bench_select(repo: LandmarkRepository, region_km: float, area_km: float, repeats: int,
                 rng: np.random.Generator, label: str) -> None:
    config = LandmarksConfig(min_spacing_m=30.0, max_count=50)
    times, cpus, counts, query_times = [], [], [], []
    half = (region_km - area_km) * 500.0
    for _ in range(repeats):
        n0, e0 = rng.uniform(-half, half, 2)
        lat, lon, _ = pymap3d.ned2geodetic(
            np.array([n0 - area_km * 500, n0 + area_km * 500]),
            np.array([e0 - area_km * 500, e0 + area_km * 500]), 0.0, *ORIGIN, 0.0)
        box = BBox(float(lon[0]), float(lat[0]), float(lon[1]), float(lat[1]))
        query_times.append(timed(partial(lambda b: counts.append(len(repo.query_area(b))), box)))
        wall, cpu = timed_cpu(partial(select_area, repo, box, config, ()))
        times.append(wall)
        cpus.append(cpu)
    ms = sorted(t * 1000 for t in times)
    print(f"{label}: select {area_km:g} km x {area_km:g} km (query + greedy, min spacing 30 m, "
          f"max 50) over {repeats} areas: median {statistics.median(ms):.1f} ms, "
          f"p90 {ms[int(0.9 * (len(ms) - 1))]:.1f} ms, this process's CPU median "
          f"{statistics.median(cpus) * 1000:.1f} ms; query_area alone median "
          f"{statistics.median(query_times) * 1000:.1f} ms; "
          f"{statistics.mean(counts):,.0f} landmarks per area; {load()}")


def server_time(repo: Any, region_km: float, area_km: float) -> None:
    """PostgreSQL's own execution time of the candidates query (EXPLAIN ANALYZE)."""
    rng = np.random.default_rng(3)
    ms = []
    for _ in range(10):
        n0, e0 = rng.uniform(-(region_km - area_km) * 500, (region_km - area_km) * 500, 2)
        lat, lon, _ = pymap3d.ned2geodetic(
            np.array([n0 - area_km * 500, n0 + area_km * 500]),
            np.array([e0 - area_km * 500, e0 + area_km * 500]), 0.0, *ORIGIN, 0.0)
        plan = repo._conn.execute(
            "EXPLAIN (ANALYZE, FORMAT JSON) SELECT id, lat_deg, lon_deg, impact, status, "
            "status_reason FROM landmarks WHERE geom && ST_MakeEnvelope(%s, %s, %s, %s, 4326)",
            (float(lon[0]), float(lat[0]), float(lon[1]), float(lat[1]))).fetchone()[0]
        ms.append(plan[0]["Execution Time"] + plan[0]["Planning Time"])
    print(f"postgis: server planning + execution of the area query (GiST): median "
          f"{statistics.median(ms):.1f} ms")


def run_sqlite(args: argparse.Namespace, records: list[Landmark], tmp: Path) -> None:
    bench_geojson_import(lambda: SqliteLandmarkRepository(tmp / "geojson.db"),
                         records[: args.geojson_count], tmp, "sqlite")
    repo = SqliteLandmarkRepository(tmp / "big.db")
    try:
        dt, cpu = timed_cpu(lambda: repo.import_landmarks(records))
        print(f"sqlite: import_landmarks of {len(records):,} records: {dt:.2f} s = "
              f"{len(records) / dt:,.0f} records/s (CPU {cpu:.2f} s; {load()})")
        bench_select(repo, args.region_km, args.area_km, args.repeats,
                     np.random.default_rng(2), "sqlite")
    finally:
        repo.close()


def run_postgis(args: argparse.Namespace, records: list[Landmark], tmp: Path) -> None:
    import psycopg
    import pytest

    from companion.landmarks.postgis_repo import PostgisLandmarkRepository
    from testsupport.pgcluster import throwaway_cluster

    try:
        with throwaway_cluster() as url:
            with psycopg.connect(url, autocommit=True) as conn:
                conn.execute("CREATE DATABASE geo")
                conn.execute("CREATE DATABASE big")
            base = url.rsplit("/", 1)[0]
            bench_geojson_import(lambda: PostgisLandmarkRepository(base + "/geo"),
                                 records[: args.geojson_count], tmp, "postgis")
            with PostgisLandmarkRepository(base + "/big") as repo:
                dt, cpu = timed_cpu(lambda: repo.import_landmarks(records))
                print(f"postgis: import_landmarks (COPY) of {len(records):,} records: "
                      f"{dt:.2f} s = {len(records) / dt:,.0f} records/s (client CPU {cpu:.2f} s; "
                      f"{load()})")
                repo._conn.execute("ANALYZE landmarks")
                bench_select(repo, args.region_km, args.area_km, args.repeats,
                             np.random.default_rng(2), "postgis")
                server_time(repo, args.region_km, args.area_km)
    except pytest.skip.Exception as err:
        print(f"postgis: skipped ({err})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--geojson-count", type=int, default=200_000)
    parser.add_argument("--region-km", type=float, default=40.0)
    parser.add_argument("--area-km", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--backend", choices=("sqlite", "postgis", "both"), default="both")
    args = parser.parse_args()
    t0 = time.perf_counter()
    records = make_landmarks(args.count, args.region_km, np.random.default_rng(1))
    print(f"generated {len(records):,} landmarks over {args.region_km:g} km x "
          f"{args.region_km:g} km in {time.perf_counter() - t0:.1f} s")
    with tempfile.TemporaryDirectory(prefix="lmc-bench-") as tmp:
        if args.backend in ("sqlite", "both"):
            run_sqlite(args, records, Path(tmp))
        if args.backend in ("postgis", "both"):
            run_postgis(args, records, Path(tmp))


if __name__ == "__main__":
    main()
