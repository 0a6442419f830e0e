"""Open a repository by location, and pull a practical map from one store into another
(``companion landmarks sync``: city-scale PostGIS -> on-board SQLite)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

from companion.core.landmark import Area
from companion.errors import InputError
from companion.extras import require
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.repository import LandmarkRepository, import_map
from companion.landmarks.selection import Selection, ZonePolygon, select_practical_map
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository

POSTGRES_SCHEMES = ("postgresql://", "postgres://")


def open_repository(location: str | Path, *, create: bool = False) -> LandmarkRepository:
    """A PostGIS repository for a ``postgresql://`` URL, else a SQLite file.

    A SQLite file that does not exist is an :class:`InputError` unless ``create`` (sqlite
    would otherwise create an empty database, and a typo would read as "0 landmarks").
    """
    text = str(location)
    if text.startswith(POSTGRES_SCHEMES):
        require("psycopg", "postgis", "a PostGIS landmark repository")
        from companion.landmarks.postgis_repo import PostgisLandmarkRepository

        return PostgisLandmarkRepository(text)
    if not create and not Path(text).exists():
        raise InputError(f"{text}: no such landmark database (companion landmarks import "
                         "creates one)")
    return SqliteLandmarkRepository(text)


def open_onboard(config: LandmarksConfig) -> SqliteLandmarkRepository:
    """The on-board database ``db_path``; an empty one is first filled from ``map_path``
    (when set), in one transaction."""
    repo = SqliteLandmarkRepository(config.db_path)
    try:
        if config.map_path and repo.count() == 0:
            import_map(repo, config.map_path)
    except BaseException:
        repo.close()
        raise
    return repo


def select_area(repo: LandmarkRepository, area: Area, config: LandmarksConfig,
                zones: Sequence[ZonePolygon], *, min_spacing_m: float | None = None,
                max_count: int | None = None, include_candidates: bool | None = None
                ) -> Selection:
    """The practical map of ``area`` from ``repo`` (arguments override the config), with
    the full records of the chosen landmarks."""
    selection = select_practical_map(
        repo.area_candidates(area),
        min_spacing_m=config.min_spacing_m if min_spacing_m is None else min_spacing_m,
        max_count=config.max_count if max_count is None else max_count,
        zones=zones,
        include_candidates=(config.include_candidates if include_candidates is None
                            else include_candidates),
        unknown_score=config.unknown_score,
    )
    return dataclasses.replace(selection, landmarks=tuple(repo.get_many(selection.ids)))


def sync_practical_map(source: LandmarkRepository, dest: LandmarkRepository, area: Area,
                       config: LandmarksConfig, zones: Sequence[ZonePolygon], *,
                       min_spacing_m: float | None = None, max_count: int | None = None,
                       include_candidates: bool | None = None) -> Selection:
    """Select in ``source`` and store the selection (with appearance images) in ``dest``.

    The destination gets the selected records in one transaction, replacing equal ids;
    nothing else in it changes.
    """
    selection = select_area(source, area, config, zones, min_spacing_m=min_spacing_m,
                            max_count=max_count, include_candidates=include_candidates)
    dest.import_landmarks(list(selection.landmarks), replace=True,
                          source=f"sync from {type(source).__name__}")
    return selection
