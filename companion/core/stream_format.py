"""The recorded frame stream folder: ``stream.toml``, ``frames.csv`` and truth CSVs.

The format is written down in docs/formats.md; this module is its one implementation.
"""

from __future__ import annotations

import csv
import json
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import IO, Any

import numpy as np

from companion.errors import InputError
from tracker.camera import CameraModel
from tracker.geometry import FloatArray

FORMAT_NAME = "landmark-companion-stream"
#: 2 added ``telemetry.csv`` (the autopilot's messages beside the frames); 1 still reads.
FORMAT_VERSION = 2

FRAMES_HEADER = ("index", "t_us", "file")
BOXES_HEADER = ("index", "landmark_id", "x", "y", "w", "h")
CORNERS = ("u_tl", "v_tl", "u_tr", "v_tr", "u_br", "v_br", "u_bl", "v_bl")
CORNER_COLUMNS = (*CORNERS, "in_view_frac", "occluded_frac")  # optional, after BOXES_HEADER
POSE_HEADER = ("index", "t_us", "north_m", "east_m", "down_m", "roll_rad", "pitch_rad", "yaw_rad")
R_COLUMNS = tuple(f"r{i}{j}" for i in range(3) for j in range(3))
CAMERA_HEADER = ("index", "t_us", "north_m", "east_m", "down_m", *R_COLUMNS)
RANGE_HEADER = ("index", "t_us", "range_m")
TELEMETRY_HEADER = ("t_us", "message", "fields")


@dataclass(frozen=True)
class Origin:
    """WGS84 origin of the local NED frame of the truth files."""

    lat: float
    lon: float
    alt_m: float


@dataclass(frozen=True)
class StreamMeta:
    """Contents of ``stream.toml``."""

    fps: float
    camera: CameraModel
    camera_id: str = "cam0"
    origin: Origin | None = None
    provenance: Mapping[str, Any] = field(default_factory=dict)
    version: int = FORMAT_VERSION


@dataclass(frozen=True)
class TruthBox:
    """A landmark's box (pixels, top-left corner, 0-based) and its four image corners.

    ``corners_px``: 4x2 (top-left, top-right, bottom-right, bottom-left of the face as seen
    from the front), possibly outside the image; ``in_view_frac``: share of the face's
    projected area inside the image; ``occluded_frac``: share of the box covered by a
    scripted occluder (simulator only; 0 otherwise).
    """

    landmark_id: str
    x: float
    y: float
    w: float
    h: float
    corners_px: FloatArray | None = None
    in_view_frac: float = 1.0
    occluded_frac: float = 0.0


@dataclass(frozen=True)
class TruthPose:
    """Vehicle position (local NED, m) and attitude (ZYX Euler, rad)."""

    north_m: float
    east_m: float
    down_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


@dataclass(frozen=True)
class TruthCamera:
    """Camera position (local NED, m) and ``R_ned_cam`` (camera-frame vectors to NED)."""

    position_ned_m: tuple[float, float, float]
    r_ned_cam: FloatArray


@dataclass(frozen=True)
class FrameTruth:
    """Everything known about one frame; ``range_m`` is None for a range-finder dropout."""

    boxes: tuple[TruthBox, ...] = ()
    pose: TruthPose | None = None
    camera: TruthCamera | None = None
    range_m: float | None = None


# --- stream.toml ------------------------------------------------------------------------


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON escapes are valid TOML escapes
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value), ensure_ascii=False)


def dumps_toml(data: Mapping[str, Any]) -> str:
    """Serialise scalars, lists and one level of tables (all this format needs)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, Mapping)]
    for key, table in data.items():
        if isinstance(table, Mapping):
            lines += ["", f"[{key}]"]
            lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def meta_to_dict(meta: StreamMeta) -> dict[str, Any]:
    """The ``stream.toml`` table for ``meta``."""
    cam = meta.camera
    out: dict[str, Any] = {
        "format": FORMAT_NAME,
        "version": meta.version,
        "fps": float(meta.fps),
        "camera_id": meta.camera_id,
        "camera": {
            "width": cam.width,
            "height": cam.height,
            "fx": float(cam.fx),
            "fy": float(cam.fy),
            "cx": float(cam.cx),
            "cy": float(cam.cy),
            "distortion": [float(d) for d in cam.distortion],
            "mount_rpy_deg": [float(a) for a in cam.mount_rpy_deg],
        },
    }
    if meta.origin is not None:
        out["origin"] = {"lat": meta.origin.lat, "lon": meta.origin.lon, "alt_m": meta.origin.alt_m}
    out["provenance"] = dict(meta.provenance)
    return out


def _need(table: Mapping[str, Any], key: str, where: str, kinds: tuple[type, ...]) -> Any:
    if key not in table:
        raise InputError(f"{where}: missing key '{key}'")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, kinds):
        names = "/".join(k.__name__ for k in kinds)
        raise InputError(f"{where}: '{key}' must be {names}, got {value!r}")
    return value


def meta_from_dict(data: Mapping[str, Any], where: str) -> StreamMeta:
    """Validate a parsed ``stream.toml``; unknown keys are ignored."""
    if data.get("format") != FORMAT_NAME:
        raise InputError(f"{where}: format must be \"{FORMAT_NAME}\", got {data.get('format')!r}")
    version = data.get("version")
    try:
        major = int(str(version).split(".")[0])
    except ValueError:
        raise InputError(f"{where}: version must be an integer, got {version!r}") from None
    if major > FORMAT_VERSION:
        raise InputError(
            f"{where}: stream format version {version} is newer than this program "
            f"supports ({FORMAT_VERSION}); upgrade landmark-companion"
        )
    fps = float(_need(data, "fps", where, (int, float)))
    cam_t = _need(data, "camera", where, (dict,))
    cw = f"{where}: [camera]"
    num = (int, float)
    camera = CameraModel(
        width=int(_need(cam_t, "width", cw, (int,))),
        height=int(_need(cam_t, "height", cw, (int,))),
        fx=float(_need(cam_t, "fx", cw, num)),
        fy=float(_need(cam_t, "fy", cw, num)),
        cx=float(_need(cam_t, "cx", cw, num)),
        cy=float(_need(cam_t, "cy", cw, num)),
        distortion=tuple(float(d) for d in cam_t.get("distortion", [0.0] * 5)),
        mount_rpy_deg=_three(cam_t.get("mount_rpy_deg", [0.0, 0.0, 0.0]), cw),
    )
    origin = None
    if "origin" in data:
        ot = _need(data, "origin", where, (dict,))
        ow = f"{where}: [origin]"
        origin = Origin(
            float(_need(ot, "lat", ow, num)),
            float(_need(ot, "lon", ow, num)),
            float(_need(ot, "alt_m", ow, num)),
        )
    return StreamMeta(
        fps=fps,
        camera=camera,
        camera_id=str(data.get("camera_id", "cam0")),
        origin=origin,
        provenance=dict(data.get("provenance", {})),
        version=major,
    )


def _three(value: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise InputError(f"{where}: 'mount_rpy_deg' must be a list of 3 numbers, got {value!r}")
    return float(value[0]), float(value[1]), float(value[2])


def read_meta(folder: Path) -> StreamMeta:
    """Read and validate ``folder/stream.toml``."""
    path = folder / "stream.toml"
    if not folder.is_dir():
        raise InputError(f"{folder}: stream folder does not exist")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: missing (not a recorded stream folder)") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: not valid TOML ({err})") from err
    return meta_from_dict(data, str(path))


# --- CSV files ---------------------------------------------------------------------------


def open_csv(
    path: Path, header: tuple[str, ...]
) -> tuple[IO[str], list[str], Iterable[list[str]]]:
    """Open a CSV, check that its header starts with ``header`` exactly; (file, names, rows)."""
    try:
        fh = path.open(newline="", encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: missing") from None
    reader = csv.reader(fh)
    first = next(reader, None)
    if first is None or tuple(c.strip() for c in first[: len(header)]) != header:
        fh.close()
        raise InputError(f"{path}: header must start with {','.join(header)}, got {first}")
    return fh, [c.strip() for c in first], reader


def _f(v: float, digits: int) -> str:
    text = f"{v:.{digits}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text  # no "-0.0"


def box_row(index: int, box: TruthBox) -> list[str]:
    """One ``truth_boxes.csv`` row."""
    row = [str(index), box.landmark_id] + [_f(v, 3) for v in (box.x, box.y, box.w, box.h)]
    if box.corners_px is not None:
        row += [_f(float(v), 3) for v in np.asarray(box.corners_px).reshape(8)]
    else:
        row += [""] * len(CORNERS)
    return [*row, _f(box.in_view_frac, 4), _f(box.occluded_frac, 4)]


def parse_box_row(row: list[str], names: list[str]) -> tuple[int, TruthBox]:
    """Inverse of :func:`box_row` (``names`` = the file's header)."""
    index = int(row[0])
    x, y, w, h = (float(v) for v in row[2:6])
    extra = {n: v.strip() for n, v in zip(names[6:], row[6:], strict=False) if v.strip()}
    corners = None
    if all(c in extra for c in CORNERS):
        corners = np.array([float(extra[c]) for c in CORNERS], dtype=np.float64).reshape(4, 2)
    in_view = float(extra.get("in_view_frac", 1.0))
    occluded = float(extra.get("occluded_frac", 0.0))
    return index, TruthBox(row[1], x, y, w, h, corners, in_view, occluded)


def pose_row(index: int, t_us: int, pose: TruthPose) -> list[str]:
    """One ``truth_pose.csv`` row."""
    vals = [pose.north_m, pose.east_m, pose.down_m]
    rads = [pose.roll_rad, pose.pitch_rad, pose.yaw_rad]
    return [str(index), str(t_us)] + [_f(v, 6) for v in vals] + [_f(v, 9) for v in rads]


def parse_pose_row(row: list[str]) -> tuple[int, int, TruthPose]:
    """Inverse of :func:`pose_row`."""
    vals = [float(v) for v in row[2:8]]
    return int(row[0]), int(row[1]), TruthPose(*vals)


def camera_row(index: int, t_us: int, cam: TruthCamera) -> list[str]:
    """One ``truth_camera.csv`` row."""
    pos = [_f(v, 6) for v in cam.position_ned_m]
    return [str(index), str(t_us), *pos, *[_f(float(v), 9) for v in cam.r_ned_cam.reshape(9)]]


def parse_camera_row(row: list[str]) -> tuple[int, TruthCamera]:
    """Inverse of :func:`camera_row`."""
    p = tuple(float(v) for v in row[2:5])
    r = np.array([float(v) for v in row[5:14]], dtype=np.float64).reshape(3, 3)
    return int(row[0]), TruthCamera((p[0], p[1], p[2]), r)


def field_names(cls: type) -> tuple[str, ...]:
    """Names of a dataclass's fields (used by docs and tests)."""
    return tuple(f.name for f in fields(cls))
