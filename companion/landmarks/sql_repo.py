"""The repository's method set over one SQL connection, written once for the SQLite
(on-board) and PostGIS (cloud) stores; a subclass gives its dialect: the parameter mark,
how ids are listed, the spatial index's table and clause, its transactions, and how an
import writes its rows (docs/landmarks.md)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Sequence
from contextlib import AbstractContextManager
from types import TracebackType
from typing import Any, ClassVar, Self

from companion.core.landmark import Area, BBox, Candidates, Landmark, filter_area
from companion.core.landmark_rows import (
    APPEARANCE_COLUMNS,
    COLUMNS,
    LandmarkRows,
    paused_gc,
    row_to_landmark,
)
from companion.errors import InputError
from companion.landmarks.repository import Progress, ScoreUpdate, check_new_ids

_COLS = ", ".join(f"l.{c}" for c in COLUMNS)
_APP_COLS = ", ".join(f"a.{c}" for c in APPEARANCE_COLUMNS)
_CANDIDATE_COLS = "l.id, l.lat_deg, l.lon_deg, l.impact, l.status, l.status_reason"


def first_line(err: BaseException) -> str:
    """The first line of a database error's message (PostgreSQL adds detail lines)."""
    lines = str(err).strip().splitlines()
    return lines[0] if lines else type(err).__name__


class SqlLandmarkRepository(ABC):
    """:class:`~companion.landmarks.repository.LandmarkRepository` over a SQL connection
    ``_conn`` (``execute(sql, params)`` returning rows, ``cursor()``, ``close()``).

    Every query names the landmarks table ``l`` and the appearances table ``a``.
    """

    #: The dialect's parameter mark (``?`` or ``%s``).
    MARK: ClassVar[str]
    #: A condition that is always true.
    TRUE: ClassVar[str]
    #: The column an appearance row refers to its landmark by.
    APPEARANCE_KEY: ClassVar[str]
    #: The FROM clause of an area query (the spatial index joined to ``landmarks l``).
    AREA_FROM: ClassVar[str]
    #: Ids per query when a list of ids is looked up.
    ID_CHUNK: ClassVar[int]
    #: The driver's exception for a broken constraint (a repeated id).
    INTEGRITY_ERROR: ClassVar[type[Exception]]

    _conn: Any

    def __enter__(self) -> Self:
        return self

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        self._conn.close()

    # ---- the dialect

    @abstractmethod
    def _transaction(self) -> AbstractContextManager[object]:
        """One write transaction: committed at the end, rolled back on any exception."""

    @abstractmethod
    def _write(self, batch: LandmarkRows, progress: Progress | None) -> None:
        """Store the rows and appearances of an import, inside its transaction."""

    @abstractmethod
    def _delete_ids(self, ids: list[str]) -> None:
        """Delete these landmarks (and their appearances), inside a transaction."""

    @abstractmethod
    def _id_in(self, ids: list[str]) -> tuple[str, Sequence[object]]:
        """The condition ``l.id`` is one of ``ids``, and its parameters."""

    @abstractmethod
    def _index_clause(self, box: BBox) -> tuple[str, Sequence[object]]:
        """The spatial index's condition for rows that may lie in ``box``."""

    def _rows(self, sql: str, params: Sequence[object]) -> Iterator[tuple[Any, ...]]:
        """The rows a query returns."""
        return iter(self._conn.execute(sql, params))

    # ---- the method set

    def count(self) -> int:
        row = self._conn.execute("SELECT count(*) FROM landmarks").fetchone()
        return int(row[0]) if row and row[0] is not None else 0

    def _bulk(self, batch: LandmarkRows, bulk_rows: int) -> bool:
        """Whether an import is large enough to rebuild the indexes after it."""
        return len(batch) >= bulk_rows and len(batch) >= self.count()

    def _existing(self, ids: list[str]) -> set[str]:
        cond, params = self._id_in(ids)
        return {r[0] for r in self._rows(f"SELECT l.id FROM landmarks l WHERE {cond}", params)}

    def import_landmarks(self, landmarks: Sequence[Landmark] | LandmarkRows, *,
                         replace: bool = False, source: str = "input",
                         progress: Progress | None = None) -> int:
        """Store every record in one transaction, all or nothing (``replace`` overwrites
        equal ids)."""
        with paused_gc():
            batch = LandmarkRows.of(landmarks)
            try:
                with self._transaction():
                    if replace:
                        self._delete_ids(batch.ids())
                    elif self.count():
                        check_new_ids(batch.ids(), self._existing, source, chunk=self.ID_CHUNK)
                    self._write(batch, progress)
            except self.INTEGRITY_ERROR as err:
                check_new_ids(batch.ids(), lambda ids: set(), source)  # names a repeated id
                raise InputError(f"{source}: rejected by the database ({first_line(err)})"
                                 ) from None
        return len(batch)

    def _select(self, where: str, params: Sequence[object], with_appearance: bool,
                area: bool = False) -> Iterator[Landmark]:
        frm = self.AREA_FROM if area else "landmarks l"
        n = len(COLUMNS)
        if with_appearance:
            key = self.APPEARANCE_KEY
            q = (f"SELECT {_COLS}, {_APP_COLS} FROM {frm} "
                 f"LEFT JOIN appearances a ON a.{key} = l.{key} WHERE {where}")
        else:
            q = f"SELECT {_COLS} FROM {frm} WHERE {where}"
        for row in self._rows(q, params):
            yield row_to_landmark(row[:n], row[n:] if with_appearance else None)

    def get(self, landmark_id: str) -> Landmark | None:
        return next(self._select(f"l.id = {self.MARK}", (landmark_id,), True), None)

    def find_by_name(self, name: str) -> list[Landmark]:
        return list(self._select(f"l.name = {self.MARK} ORDER BY l.id", (name,), True))

    def _area_where(self, area: Area) -> tuple[str, list[object]]:
        """The index's condition and the exact box (the index may be coarser)."""
        b = area.bbox()
        index, params = self._index_clause(b)
        m = self.MARK
        return (f"{index} AND l.lon_deg BETWEEN {m} AND {m} AND l.lat_deg BETWEEN {m} AND {m}",
                [*params, b.min_lon_deg, b.max_lon_deg, b.min_lat_deg, b.max_lat_deg])

    def query_area(self, area: Area, *, with_appearance: bool = False) -> list[Landmark]:
        where, params = self._area_where(area)
        return filter_area(list(self._select(f"{where} ORDER BY l.id", params,
                                             with_appearance, area=True)), area)

    def area_candidates(self, area: Area) -> Candidates:
        where, params = self._area_where(area)
        rows = list(self._rows(f"SELECT {_CANDIDATE_COLS} FROM {self.AREA_FROM} WHERE {where}",
                               params))
        return Candidates.from_rows(rows, area)

    def get_many(self, ids: Sequence[str]) -> list[Landmark]:
        found: dict[str, Landmark] = {}
        for start in range(0, len(ids), self.ID_CHUNK):
            cond, params = self._id_in(list(ids[start:start + self.ID_CHUNK]))
            found.update((lm.id, lm) for lm in self._select(cond, params, True))
        return [found[i] for i in ids if i in found]

    def iter_all(self, *, with_appearance: bool = True) -> Iterator[Landmark]:
        return self._select(f"{self.TRUE} ORDER BY l.id", (), with_appearance)

    def update_scores(self, updates: Iterable[ScoreUpdate]) -> int:
        rows = [(u.scores.distinctiveness, u.scores.flatness, u.scores.static, u.scores.impact,
                 u.status, u.status_reason, u.id) for u in updates]
        m = self.MARK
        with self._transaction():
            cur = self._conn.cursor()
            try:
                cur.executemany(
                    f"UPDATE landmarks SET distinctiveness = {m}, flatness = {m}, static = {m}, "
                    f"impact = {m}, status = {m}, status_reason = {m} WHERE id = {m}", rows)
            finally:
                cur.close()
        return len(rows)
