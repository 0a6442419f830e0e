"""The repository interface shared by the SQLite (on-board) and PostGIS (cloud) stores,
and a map file's import into one; the rows both store are :mod:`companion.core.landmark_rows`."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from companion.core.landmark import Area, Candidates, Landmark, Scores, Status
from companion.core.landmark_rows import LandmarkRows, paused_gc
from companion.core.map_file import read_rows

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


def import_map(repo: LandmarkRepository, path: str | Path, *, replace: bool = False,
               progress: Progress | None = None) -> int:
    """Validate the whole map first, then store it in one transaction (all or nothing)."""
    with paused_gc():
        rows = read_rows(path)
        return repo.import_landmarks(rows, replace=replace, source=str(path), progress=progress)
