"""Landmark database: records, admission scores, practical maps, geodesy and storage.

The source paper's sections 2.1-2.3: a *cloud repository* of candidate landmarks with
admission criteria (:mod:`.scores`), a *practical map* chosen from it for one area
(:mod:`.selection`), and the table between landmark names and coordinates
(:mod:`.geodesy`).  Storage is SQLite on board (:mod:`.sqlite_repo`) and PostgreSQL +
PostGIS in the cloud (:mod:`.postgis_repo`), behind one interface (:mod:`.repository`).
"""

from companion.core.landmark import (
    Appearance,
    Area,
    BBox,
    Circle,
    Landmark,
    Scores,
    parse_area,
)

__all__ = ["Appearance", "Area", "BBox", "Circle", "Landmark", "Scores", "parse_area"]
