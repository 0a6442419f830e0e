"""The repository interface shared by the SQLite (on-board) and PostGIS (cloud) stores,
and the row <-> record conversion both of them use (:class:`LandmarkRows`: what an
import writes)."""

from __future__ import annotations

import gc
import json
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any, Protocol, cast

import numpy as np
import numpy.typing as npt

from companion.landmarks.record import (
    Appearance,
    Area,
    Candidates,
    Category,
    Landmark,
    Scores,
    Status,
)

#: Columns of the ``landmarks`` table in the order of :func:`landmark_to_row`.
COLUMNS: tuple[str, ...] = (
    "id", "name", "category", "lat_deg", "lon_deg", "alt_m", "width_m", "height_m",
    "facing_deg", "status", "status_reason", "distinctiveness", "flatness", "static",
    "impact", "points_json", "sightings_json",
)
#: Columns of the ``appearances`` table after the landmark key.
APPEARANCE_COLUMNS: tuple[str, ...] = ("media_type", "data", "box_x", "box_y", "box_w", "box_h")
_LAT, _LON = itemgetter(COLUMNS.index("lat_deg")), itemgetter(COLUMNS.index("lon_deg"))

Progress = Callable[[int], None]


@dataclass(frozen=True, slots=True)
class ScoreUpdate:
    """New scores and status for one landmark (see :mod:`companion.landmarks.scores`)."""

    id: str
    scores: Scores
    status: Status
    status_reason: str


class LandmarkRepository(Protocol):
    """What the application needs from a landmark store.

    ``import_landmarks`` (records, or the same as :class:`LandmarkRows`) is all or
    nothing: on any error (or if the process dies) the store is left exactly as it was.
    ``query_area`` returns the landmarks inside the area, without appearance images
    unless asked; ``area_candidates`` returns only what practical-map selection needs, as
    columns (fast); ``get_many`` returns full records (with appearance) in the order of
    the ids, skipping unknown ids.
    """

    def schema_version(self) -> int: ...

    def count(self) -> int: ...

    def import_landmarks(self, landmarks: Sequence[Landmark] | LandmarkRows, *,
                         replace: bool = False, source: str = "input",
                         progress: Progress | None = None) -> int: ...

    def get(self, landmark_id: str) -> Landmark | None: ...

    def find_by_name(self, name: str) -> list[Landmark]: ...

    def query_area(self, area: Area, *, with_appearance: bool = False) -> list[Landmark]: ...

    def area_candidates(self, area: Area) -> Candidates: ...

    def get_many(self, ids: Sequence[str]) -> list[Landmark]: ...

    def iter_all(self, *, with_appearance: bool = True) -> Iterator[Landmark]: ...

    def update_scores(self, updates: Iterable[ScoreUpdate]) -> int: ...

    def close(self) -> None: ...


@contextmanager
def paused_gc() -> Iterator[None]:
    """Pause the cyclic garbage collector during a bulk load.

    Loading a map creates millions of small containers that all stay alive; the collector
    would traverse them again and again (measured: ~40 % of the parse time).  Nothing
    here makes reference cycles, so pausing loses nothing; the previous state returns.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def triples_json(points: Sequence[tuple[float, float, float]]) -> str | None:
    """The ``points_json`` / ``sightings_json`` column value (``None`` when empty)."""
    return json.dumps(points) if points else None


def landmark_to_row(lm: Landmark) -> tuple[Any, ...]:
    """The ``COLUMNS`` values of a record."""
    s = lm.scores
    return (
        lm.id, lm.name, lm.category, lm.lat_deg, lm.lon_deg, lm.alt_m, lm.width_m,
        lm.height_m, lm.facing_deg, lm.status, lm.status_reason, s.distinctiveness,
        s.flatness, s.static, s.impact, triples_json(lm.points_m), triples_json(lm.sightings),
    )


def appearance_to_row(app: Appearance) -> tuple[Any, ...]:
    box = app.box_px or (None, None, None, None)
    return (app.media_type, app.data, *box)


def _triples(text: str | None) -> tuple[tuple[float, float, float], ...]:
    if not text:
        return ()
    return tuple((float(p[0]), float(p[1]), float(p[2])) for p in json.loads(text))


def row_to_landmark(row: Sequence[Any], app: Sequence[Any] | None = None) -> Landmark:
    """A record from ``COLUMNS`` values and optional ``APPEARANCE_COLUMNS`` values."""
    appearance = None
    if app is not None and app[0] is not None:
        box = None if app[2] is None else (int(app[2]), int(app[3]), int(app[4]), int(app[5]))
        appearance = Appearance(str(app[0]), bytes(app[1]), box)
    return Landmark(
        id=row[0], name=row[1], category=cast(Category, row[2]), lat_deg=row[3], lon_deg=row[4],
        alt_m=row[5], width_m=row[6], height_m=row[7], facing_deg=row[8],
        status=cast(Status, row[9]), status_reason=row[10],
        scores=Scores(row[11], row[12], row[13], row[14]), appearance=appearance,
        points_m=_triples(row[15]), sightings=_triples(row[16]),
    )


@dataclass(frozen=True)
class LandmarkRows:
    """Records as the rows an import writes: their ``COLUMNS`` values, and the
    ``APPEARANCE_COLUMNS`` values of those with an appearance image, by row index.

    A validated map becomes rows directly (``geojson_io.read_rows``): making a frozen
    :class:`Landmark` per feature only to take it apart again costs ~2 us a record.
    """

    rows: list[tuple[Any, ...]]
    appearances: dict[int, tuple[Any, ...]] = field(default_factory=dict)

    @classmethod
    def of(cls, records: Sequence[Landmark] | LandmarkRows) -> LandmarkRows:
        if isinstance(records, LandmarkRows):
            return records
        return cls([landmark_to_row(lm) for lm in records],
                   {i: appearance_to_row(lm.appearance) for i, lm in enumerate(records)
                    if lm.appearance is not None})

    def __len__(self) -> int:
        return len(self.rows)

    def ids(self) -> list[str]:
        return [row[0] for row in self.rows]

    def landmarks(self) -> list[Landmark]:
        apps = self.appearances
        return [row_to_landmark(row, apps.get(i)) for i, row in enumerate(self.rows)]

    def positions(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(lat_deg, lon_deg)`` arrays of the rows."""
        n = len(self.rows)
        return (np.fromiter(map(_LAT, self.rows), np.float64, n),
                np.fromiter(map(_LON, self.rows), np.float64, n))


def check_new_ids(ids: Sequence[str], existing: Callable[[list[str]], set[str]],
                  source: str, chunk: int = 500) -> None:
    """Raise InputError for the first id that is already stored (or repeated)."""
    from companion.errors import InputError

    seen: dict[str, int] = {}
    for i, lm_id in enumerate(ids):
        first = seen.setdefault(lm_id, i)
        if first != i:
            raise InputError(f"{source}: feature {i}: id: duplicate id {lm_id!r} "
                             f"(already used by feature {first})")
    for start in range(0, len(ids), chunk):
        part = list(ids[start:start + chunk])
        found = existing(part)
        if found:
            i = next(k for k, x in enumerate(part) if x in found) + start
            raise InputError(f"{source}: feature {i}: id: {ids[i]!r} already exists in "
                             "the database (import with replace to overwrite)")
