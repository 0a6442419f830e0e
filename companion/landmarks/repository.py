"""The repository interface shared by the SQLite (on-board) and PostGIS (cloud) stores,
and the row <-> record conversion both of them use."""

from __future__ import annotations

import gc
import json
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Protocol, cast

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

    ``import_landmarks`` is all or nothing: on any error (or if the process dies) the
    store is left exactly as it was.  ``query_area`` returns the landmarks inside the
    area, without appearance images unless asked; ``area_candidates`` returns only what
    practical-map selection needs, as columns (fast); ``get_many`` returns full records
    (with appearance) in the order of the ids, skipping unknown ids.
    """

    def schema_version(self) -> int: ...

    def count(self) -> int: ...

    def import_landmarks(self, landmarks: Sequence[Landmark], *, replace: bool = False,
                         source: str = "input", progress: Progress | None = None) -> int: ...

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


def _points_json(points: tuple[tuple[float, float, float], ...]) -> str | None:
    return json.dumps(points) if points else None


def landmark_to_row(lm: Landmark) -> tuple[Any, ...]:
    """The ``COLUMNS`` values of a record."""
    s = lm.scores
    return (
        lm.id, lm.name, lm.category, lm.lat_deg, lm.lon_deg, lm.alt_m, lm.width_m,
        lm.height_m, lm.facing_deg, lm.status, lm.status_reason, s.distinctiveness,
        s.flatness, s.static, s.impact, _points_json(lm.points_m), _points_json(lm.sightings),
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


def check_new_ids(landmarks: Sequence[Landmark], existing: Callable[[list[str]], set[str]],
                  source: str, chunk: int = 500) -> None:
    """Raise InputError for the first record whose id is already stored (or repeated)."""
    from companion.errors import InputError

    seen: dict[str, int] = {}
    for i, lm in enumerate(landmarks):
        first = seen.setdefault(lm.id, i)
        if first != i:
            raise InputError(f"{source}: feature {i}: id: duplicate id {lm.id!r} "
                             f"(already used by feature {first})")
    for start in range(0, len(landmarks), chunk):
        ids = [lm.id for lm in landmarks[start:start + chunk]]
        found = existing(ids)
        if found:
            i = next(k for k, x in enumerate(ids) if x in found) + start
            raise InputError(f"{source}: feature {i}: id: {ids[i - start]!r} already exists in "
                             "the database (import with replace to overwrite)")
