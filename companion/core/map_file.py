"""Landmark map GeoJSON: validation into table rows (``LandmarkRows``, what an import
writes) or :class:`Landmark` records, and export.

Format (DESIGN.md, "Landmark map"): a FeatureCollection of Point features with
coordinates ``[lon, lat, alt_m]``; the Feature ``id`` (string, or integer kept as its
decimal text) is the landmark id; properties

* required: ``name`` (non-empty string), ``category`` (signpost | wall_image | logo |
  other), ``width_m`` and ``height_m`` (> 0);
* optional: ``facing_deg`` (0 <= x < 360, absent or null = lying flat, facing up),
  ``status`` (candidate | approved | rejected) and ``status_reason``, ``appearance``
  (a path relative to the map file, or a ``data:`` URI), ``appearance_box`` (``[x, y, w,
  h]`` pixels of the landmark inside the appearance image), ``scores`` (object with
  ``distinctiveness``, ``flatness``, ``static``, ``impact``, each in [0, 1] or null),
  ``points_m`` (list of ``[x, y, z]`` metres on the face) and ``sightings`` (list of
  ``[lon, lat, alt_m]`` where it was seen).

Every problem is reported as one line naming the file, the feature index and the field,
e.g. ``map.geojson: feature 3: properties.category: expected one of signpost, wall_image,
logo, other, got "tree"``.  Unknown properties are ignored.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import mimetypes
import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import orjson

from companion.core.landmark import CATEGORIES, STATUSES, Appearance, Landmark, Point3
from companion.core.landmark_rows import (
    LandmarkRows,
    appearance_to_row,
    paused_gc,
    triples_json,
)
from companion.errors import InputError

_SCORE_KEYS = ("distinctiveness", "flatness", "static", "impact")


class _FieldError(Exception):
    """A bad field inside one feature; turned into an InputError with the index."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")


def _show(value: object) -> str:
    text = json.dumps(value) if not isinstance(value, bytes) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _number(value: object, field: str, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, hi_open: bool = False) -> float:
    t = type(value)
    if t is float or t is int:  # fast path; bool is not int here, NaN fails the range test
        x = float(value)  # type: ignore[arg-type]
        if ((lo is None or (x > lo if lo_open else x >= lo))
                and (hi is None or (x < hi if hi_open else x <= hi)) and math.isfinite(x)):
            return x
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _FieldError(field, f"expected a number, got {_show(value)}")
    lo_t = "" if lo is None else (f"> {lo:g}" if lo_open else f">= {lo:g}")
    hi_t = "" if hi is None else (f"< {hi:g}" if hi_open else f"<= {hi:g}")
    rng = " and ".join(t for t in (lo_t, hi_t) if t)
    raise _FieldError(field, f"expected a number {rng}, got {_show(value)}")


def _triples(value: object, field: str, geographic: bool) -> tuple[Point3, ...]:
    if not isinstance(value, list):
        raise _FieldError(field, f"expected a list of [x, y, z], got {_show(value)}")
    out: list[Point3] = []
    for j, p in enumerate(value):
        f = f"{field}[{j}]"
        if not isinstance(p, list) or len(p) != 3:
            raise _FieldError(f, f"expected [x, y, z], got {_show(p)}")
        if geographic:
            out.append((_number(p[0], f + "[0]", -180, 180), _number(p[1], f + "[1]", -90, 90),
                        _number(p[2], f + "[2]")))
        else:
            out.append((_number(p[0], f + "[0]"), _number(p[1], f + "[1]"),
                        _number(p[2], f + "[2]")))
    return tuple(out)


def _appearance(ref: object, box: object, base_dir: Path) -> Appearance | None:
    if ref is None:
        return None
    field = "properties.appearance"
    if not isinstance(ref, str) or not ref:
        raise _FieldError(field, f"expected a relative path or a data URI, got {_show(ref)}")
    if ref.startswith("data:"):
        header, sep, payload = ref[5:].partition(",")
        if not sep or not header.endswith(";base64"):
            raise _FieldError(field, "expected a data URI like data:image/png;base64,...")
        try:
            data = base64.b64decode(payload, validate=True)
        except binascii.Error as err:
            raise _FieldError(field, f"bad base64 in data URI ({err})") from None
        media_type = header[: -len(";base64")] or "application/octet-stream"
    else:
        path = base_dir / ref
        try:
            data = path.read_bytes()
        except OSError as err:
            raise _FieldError(field, f"cannot read {str(path)!r} ({err.strerror})") from None
        media_type = mimetypes.guess_type(ref)[0] or "application/octet-stream"
    box_px = None
    if box is not None:
        bf = "properties.appearance_box"
        if (not isinstance(box, list) or len(box) != 4
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in box)
                or box[0] < 0 or box[1] < 0 or box[2] <= 0 or box[3] <= 0):
            raise _FieldError(bf, f"expected [x, y, w, h] integers (w, h > 0), got {_show(box)}")
        box_px = (box[0], box[1], box[2], box[3])
    return Appearance(media_type, data, box_px)


_NO_SCORES = (None, None, None, None)


def _scores(value: object) -> tuple[float | None, ...]:
    """The four scores in ``_SCORE_KEYS`` order."""
    if value is None:
        return _NO_SCORES
    if not isinstance(value, dict):
        raise _FieldError("properties.scores", f"expected an object, got {_show(value)}")
    vals = tuple(map(value.get, _SCORE_KEYS))
    for v in vals:
        if v is not None and not (type(v) is float and 0.0 <= v <= 1.0):
            break  # not the usual case: check each one, naming the bad one
    else:
        return vals
    return tuple(None if v is None else _number(v, f"properties.scores.{key}", 0.0, 1.0)
                 for key, v in zip(_SCORE_KEYS, vals, strict=True))


def _feature_id(feature: dict[str, Any]) -> str:
    fid = feature.get("id")
    if isinstance(fid, str) and fid:
        return fid
    if isinstance(fid, int) and not isinstance(fid, bool):
        return str(fid)
    if fid is None:
        raise _FieldError("id", "required (a non-empty string or an integer)")
    raise _FieldError("id", f"expected a non-empty string or an integer, got {_show(fid)}")


def _position(geometry: object) -> tuple[float, float, float]:
    if not isinstance(geometry, dict) or geometry.get("type") != "Point":
        raise _FieldError("geometry", "expected a Point geometry")
    c = geometry.get("coordinates")
    if not isinstance(c, list) or len(c) != 3:
        raise _FieldError("geometry.coordinates", f"expected [lon, lat, alt_m], got {_show(c)}")
    lon, lat, alt = c
    if (type(lon) is float and type(lat) is float and type(alt) is float
            and -180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0 and math.isfinite(alt)):
        return lon, lat, alt  # fast path: the usual case
    return (
        _number(c[0], "geometry.coordinates[0] (longitude)", -180, 180),
        _number(c[1], "geometry.coordinates[1] (latitude)", -90, 90),
        _number(c[2], "geometry.coordinates[2] (altitude)"),
    )


def _required(props: dict[str, Any], key: str) -> object:
    if key not in props or props[key] is None:
        raise _FieldError(f"properties.{key}", "required property is missing")
    return props[key]


def feature_to_row(feature: object, base_dir: Path
                   ) -> tuple[tuple[Any, ...], Appearance | None]:
    """One GeoJSON feature as a ``repository.COLUMNS`` row and its appearance image;
    raises ``_FieldError`` naming the field."""
    if not isinstance(feature, dict) or feature.get("type") != "Feature":
        raise _FieldError("type", "expected a GeoJSON Feature object")
    fid = _feature_id(feature)
    lon, lat, alt = _position(feature.get("geometry"))
    props = feature.get("properties")
    if not isinstance(props, dict):
        raise _FieldError("properties", f"expected an object, got {_show(props)}")
    name = _required(props, "name")
    if not isinstance(name, str) or not name.strip():
        raise _FieldError("properties.name", f"expected a non-empty string, got {_show(name)}")
    category = _required(props, "category")
    if category not in CATEGORIES:
        raise _FieldError("properties.category",
                          f"expected one of {', '.join(CATEGORIES)}, got {_show(category)}")
    width = _number(_required(props, "width_m"), "properties.width_m", 0.0, lo_open=True)
    height = _number(_required(props, "height_m"), "properties.height_m", 0.0, lo_open=True)
    facing = props.get("facing_deg")
    if facing is not None:
        facing = _number(facing, "properties.facing_deg", 0.0, 360.0, hi_open=True)
    status = props.get("status", "candidate")
    if status not in STATUSES:
        raise _FieldError("properties.status",
                          f"expected one of {', '.join(STATUSES)}, got {_show(status)}")
    reason = props.get("status_reason", "")
    if not isinstance(reason, str):
        raise _FieldError("properties.status_reason", f"expected a string, got {_show(reason)}")
    d, f, s, i = _scores(props.get("scores"))
    appearance = _appearance(props.get("appearance"), props.get("appearance_box"), base_dir)
    points, sightings = props.get("points_m"), props.get("sightings")
    if points is not None:
        points = triples_json(_triples(points, "properties.points_m", False))
    if sightings is not None:
        sightings = triples_json(_triples(sightings, "properties.sightings", True))
    return (fid, name, category, lat, lon, alt, width, height, facing, status, reason,
            d, f, s, i, points, sightings), appearance


def parse_feature_collection(doc: object, source: str, base_dir: Path) -> LandmarkRows:
    """Validate a decoded GeoJSON document into rows; raise :class:`InputError` on the
    first problem."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise InputError(f"{source}: not a GeoJSON FeatureCollection (top-level \"type\")")
    features = doc.get("features")
    if not isinstance(features, list):
        raise InputError(f"{source}: features: expected a list of Feature objects")
    rows: list[tuple[Any, ...]] = []
    apps: dict[int, tuple[Any, ...]] = {}
    seen: dict[str, int] = {}
    for i, feature in enumerate(features):
        try:
            row, app = feature_to_row(feature, base_dir)
        except _FieldError as err:
            raise InputError(f"{source}: feature {i}: {err}") from None
        first = seen.setdefault(row[0], i)
        if first != i:
            raise InputError(f"{source}: feature {i}: id: duplicate id {row[0]!r} "
                             f"(already used by feature {first})")
        rows.append(row)
        if app is not None:
            apps[i] = appearance_to_row(app)
    return LandmarkRows(rows, apps)


def read_rows(path: str | Path) -> LandmarkRows:
    """Read and validate a landmark map file (appearance paths relative to it) into the
    rows an import writes."""
    p = Path(path)
    try:
        text = p.read_bytes()
    except OSError as err:
        raise InputError(f"{p}: cannot read landmark map ({err.strerror})") from None
    with paused_gc():
        try:
            doc = orjson.loads(text)
        except orjson.JSONDecodeError as err:
            raise InputError(f"{p}: not valid JSON ({err})") from None
        return parse_feature_collection(doc, str(p), p.parent)


def read_map(path: str | Path) -> list[Landmark]:
    """Read and validate a landmark map file (appearance paths relative to it)."""
    with paused_gc():
        return read_rows(path).landmarks()


def landmark_to_feature(lm: Landmark, appearance_ref: str | None) -> dict[str, Any]:
    """A record as a GeoJSON feature (``appearance_ref`` already written by the caller)."""
    props: dict[str, Any] = {
        "name": lm.name, "category": lm.category, "width_m": lm.width_m, "height_m": lm.height_m,
    }
    if lm.facing_deg is not None:
        props["facing_deg"] = lm.facing_deg
    props["status"] = lm.status
    if lm.status_reason:
        props["status_reason"] = lm.status_reason
    scores = {k: getattr(lm.scores, k) for k in _SCORE_KEYS if getattr(lm.scores, k) is not None}
    if scores:
        props["scores"] = scores
    if appearance_ref is not None and lm.appearance is not None:
        props["appearance"] = appearance_ref
        if lm.appearance.box_px is not None:
            props["appearance_box"] = list(lm.appearance.box_px)
    if lm.points_m:
        props["points_m"] = [list(p) for p in lm.points_m]
    if lm.sightings:
        props["sightings"] = [list(p) for p in lm.sightings]
    return {
        "type": "Feature", "id": lm.id,
        "geometry": {"type": "Point", "coordinates": [lm.lon_deg, lm.lat_deg, lm.alt_m]},
        "properties": props,
    }


def data_uri(app: Appearance) -> str:
    return f"data:{app.media_type};base64,{base64.b64encode(app.data).decode('ascii')}"


def write_map(path: str | Path, landmarks: Iterable[Landmark], embed_appearance: bool = False
              ) -> int:
    """Write a map atomically (temp file + rename); return the number of features.

    Appearance images go to ``<map stem>.appearance/<id>.<ext>`` beside the map (paths in
    the map are relative to it), or into data URIs with ``embed_appearance``.
    """
    p = Path(path)
    tmp = p.with_name(p.name + ".tmp")
    img_dir = p.with_name(p.stem + ".appearance")
    used: set[str] = set()
    n = 0
    with tmp.open("w", encoding="utf-8") as out:
        out.write('{"type": "FeatureCollection", "features": [\n')
        for lm in landmarks:
            ref = None
            if lm.appearance is not None:
                ref = data_uri(lm.appearance) if embed_appearance else _write_image(
                    img_dir, lm, used)
            out.write((",\n" if n else "") + orjson.dumps(landmark_to_feature(lm, ref)).decode())
            n += 1
        out.write("\n]}\n")
    os.replace(tmp, p)
    return n


def _write_image(img_dir: Path, lm: Landmark, used: set[str]) -> str:
    assert lm.appearance is not None
    ext = mimetypes.guess_extension(lm.appearance.media_type) or ".bin"
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", lm.id)
    name, k = stem + ext, 1
    while name.lower() in used:
        name, k = f"{stem}_{k}{ext}", k + 1
    used.add(name.lower())
    img_dir.mkdir(parents=True, exist_ok=True)
    (img_dir / name).write_bytes(lm.appearance.data)
    return f"{img_dir.name}/{name}"
