"""A landmark record as table rows (``COLUMNS``, ``APPEARANCE_COLUMNS``) and back:
what a map file validates into and what the SQLite and PostGIS repositories store
(:class:`LandmarkRows`)."""

from __future__ import annotations

import gc
import json
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from companion.core.landmark import Appearance, Category, Landmark, Scores, Status

#: Columns of the ``landmarks`` table in the order of :func:`landmark_to_row`.
COLUMNS: tuple[str, ...] = (
    "id", "name", "category", "lat_deg", "lon_deg", "alt_m", "width_m", "height_m",
    "facing_deg", "status", "status_reason", "distinctiveness", "flatness", "static",
    "impact", "points_json", "sightings_json",
)
#: Columns of the ``appearances`` table after the landmark key.
APPEARANCE_COLUMNS: tuple[str, ...] = ("media_type", "data", "box_x", "box_y", "box_w", "box_h")
_LAT, _LON = itemgetter(COLUMNS.index("lat_deg")), itemgetter(COLUMNS.index("lon_deg"))


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

    A validated map becomes rows directly (``companion.core.map_file.read_rows``): making a frozen
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
