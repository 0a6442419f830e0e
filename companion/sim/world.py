"""The simulated world: landmarks from a GeoJSON landmark map as textured quads, facades
behind the wall images, poles under the signposts, and a ground plane."""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
import pymap3d

from companion.core.frames import ImageU8
from companion.core.landmark import Appearance, Landmark
from companion.core.map_file import read_map
from companion.core.stream_format import Origin
from companion.errors import InputError
from companion.sim import textures
from tracker.geometry import FloatArray
from tracker.pose.landmarks import corners_about

DOWN = np.array([0.0, 0.0, 1.0])
#: The generated face of a landmark without a reference image, by category (else a poster).
FACADE_CATEGORIES = ("wall_image", "logo")  # hung on a facade (signposts stand on poles)
TEXTURES = {"signpost": textures.signpost_texture, "logo": textures.logo_texture}


@dataclass(frozen=True)
class WorldConfig:
    """Ground, facades and poles around the landmarks (metres, BGR colours)."""

    ground_down_m: float = 0.0  # the ground plane's NED down coordinate
    ground_extent_m: float = 256.0  # side of the textured ground square around the origin
    ground_texture_px: int = field(default=1024, metadata={"ge": 64})
    far_ground_bgr: tuple[int, int, int] = (85, 112, 95)
    facade_margin_m: float = field(default=8.0, metadata={"ge": 0})
    facade_extra_height_m: float = field(default=4.0, metadata={"ge": 0})
    facade_gap_m: float = field(default=0.02, metadata={"gt": 0})
    pole_width_m: float = field(default=0.08, metadata={"gt": 0})


@dataclass(frozen=True, eq=False)
class Quad:
    """A planar rectangle in NED: corners TL, TR, BR, BL (4x3) as seen from its front.

    ``texture`` None means a plain ``colour_bgr`` fill; ``two_sided`` quads are drawn from
    behind too (ground, poles).  ``landmark_id`` is set only for landmarks (truth).
    """

    corners_ned: FloatArray
    texture: ImageU8 | None = None
    colour_bgr: tuple[int, int, int] = (128, 128, 128)
    two_sided: bool = False
    landmark_id: str = ""

    @cached_property
    def centre_ned(self) -> FloatArray:
        """Mean of the corners (once: the renderer asks every frame)."""
        return np.asarray(self.corners_ned.mean(axis=0), dtype=np.float64)

    @cached_property
    def normal_ned(self) -> FloatArray:
        """Unit outward normal (towards the viewer of the front face; once)."""
        c = self.corners_ned
        n = np.cross(c[3] - c[0], c[1] - c[0])  # (BL-TL) x (TR-TL) points out of the face
        return np.asarray(n / np.linalg.norm(n), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class SimLandmark:
    """One landmark of the map, placed in local NED."""

    landmark_id: str
    name: str
    category: str
    centre_ned: FloatArray
    width_m: float
    height_m: float
    facing_deg: float | None
    quad: Quad


def face_corners(
    centre: FloatArray, width_m: float, height_m: float, facing_deg: float | None
) -> FloatArray:
    """TL, TR, BR, BL of a face centred at ``centre`` (NED), as the pose solver defines
    them (:func:`tracker.pose.landmarks.corners_about`)."""
    return corners_about(centre, width_m, height_m, facing_deg)


def seeded_rng(seed: int, key: str) -> np.random.Generator:
    """A generator that depends only on the world seed and a name (textures per id)."""
    return np.random.default_rng([seed, zlib.crc32(key.encode("utf-8"))])


def texture_from_appearance(app: Appearance, where: str) -> ImageU8:
    """The face's texture from a map's reference image: its ``box_px``, or the central
    half of the image (the landmark database's convention when there is no box)."""
    img = cv2.imdecode(np.frombuffer(app.data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"{where}: appearance is not a readable image")
    h, w = img.shape[:2]
    x, y, bw, bh = app.box_px or (w // 4, h // 4, max(1, w // 2), max(1, h // 2))
    face = img[y : y + bh, x : x + bw]
    if face.size == 0:
        raise InputError(f"{where}: appearance_box {app.box_px} lies outside the image")
    return np.ascontiguousarray(face, dtype=np.uint8)


def sim_landmark(record: Landmark, origin: Origin, seed: int) -> SimLandmark:
    """A landmark record (``companion.landmarks``) placed in NED as a textured quad."""
    n_m, e_m, d_m = pymap3d.geodetic2ned(record.lat_deg, record.lon_deg, record.alt_m,
                                         origin.lat, origin.lon, origin.alt_m)
    centre = np.array([n_m, e_m, d_m], dtype=np.float64)
    lid = record.id
    if record.appearance is not None:
        texture = texture_from_appearance(record.appearance, f"landmark {lid}")
    else:
        rng = seeded_rng(seed, lid)
        make = TEXTURES.get(record.category, textures.poster_texture)
        texture = make(rng, record.width_m, record.height_m, record.name)
    corners = face_corners(centre, record.width_m, record.height_m, record.facing_deg)
    quad = Quad(corners, texture, landmark_id=lid)
    return SimLandmark(lid, record.name, record.category, centre, record.width_m,
                       record.height_m, record.facing_deg, quad)


def load_landmark_map(path: Path, origin: Origin, seed: int = 0) -> list[SimLandmark]:
    """Read a GeoJSON landmark map (validated by ``companion.core.map_file``) and
    place every landmark in NED about ``origin``; the point is the face's centre."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: landmark map is missing")
    out = []
    for record in read_map(path):
        try:
            out.append(sim_landmark(record, origin, seed))
        except InputError as err:
            raise InputError(f"{path}: {err}") from None
    return out


@dataclass(eq=False)
class World:
    """Landmarks plus the scenery built around them (facades, poles, ground)."""

    landmarks: list[SimLandmark]
    config: WorldConfig = field(default_factory=WorldConfig)
    seed: int = 0
    facades: list[Quad] = field(init=False)
    poles: list[Quad] = field(init=False)
    ground: Quad = field(init=False)
    far_ground: Quad = field(init=False)

    def __post_init__(self) -> None:
        cfg = self.config
        self.facades = self._facades()
        self.poles = [p for lm in self.landmarks if (p := self._pole(lm)) is not None]
        half, g = cfg.ground_extent_m / 2.0, cfg.ground_down_m
        rng = seeded_rng(self.seed, "ground")
        tex = textures.ground_texture(rng, cfg.ground_texture_px)
        self.ground = Quad(_flat_square(half, g), tex, two_sided=True)
        self.far_ground = Quad(_flat_square(20_000.0, g + 1e-3), None, cfg.far_ground_bgr, True)

    def _facades(self) -> list[Quad]:
        """One wall per plane of wall images and logos, from the ground to above the highest one."""
        cfg = self.config
        groups: dict[tuple[float, float], list[SimLandmark]] = {}
        for lm in self.landmarks:
            if lm.category not in FACADE_CATEGORIES or lm.facing_deg is None:
                continue
            offset = float(lm.quad.normal_ned @ lm.centre_ned)
            groups.setdefault((round(lm.facing_deg % 360.0, 1), round(offset, 1)), []).append(lm)
        out = []
        for (facing, _), members in sorted(groups.items()):
            n = members[0].quad.normal_ned
            right = members[0].quad.corners_ned[1] - members[0].quad.corners_ned[0]
            right /= np.linalg.norm(right)
            corners = np.concatenate([m.quad.corners_ned for m in members])
            along = corners @ right
            lo, hi = along.min() - cfg.facade_margin_m, along.max() + cfg.facade_margin_m
            top_down = float(corners[:, 2].min()) - cfg.facade_extra_height_m
            height, width = cfg.ground_down_m - top_down, hi - lo
            anchor = members[0].centre_ned - n * cfg.facade_gap_m
            centre = anchor + right * ((lo + hi) / 2.0 - float(anchor @ right))
            centre[2] = (cfg.ground_down_m + top_down) / 2.0
            rng = seeded_rng(self.seed, f"facade:{members[0].landmark_id}")
            tex = textures.facade_texture(rng, width, height)
            out.append(Quad(face_corners(centre, width, height, facing), tex))
        return out

    def _pole(self, lm: SimLandmark) -> Quad | None:
        """A grey pole from a signpost's bottom edge down to the ground."""
        if lm.category != "signpost" or lm.facing_deg is None:
            return None
        bottom = float(lm.quad.corners_ned[3, 2])
        length = self.config.ground_down_m - bottom
        if length <= 0:
            return None
        n = lm.quad.normal_ned
        centre = lm.centre_ned - n * 0.01
        centre[2] = bottom + length / 2.0
        corners = face_corners(centre, self.config.pole_width_m, length, lm.facing_deg)
        return Quad(corners, None, (110, 110, 115), two_sided=True)

    def landmark(self, landmark_id: str) -> SimLandmark:
        """The landmark with this id (KeyError if none)."""
        for lm in self.landmarks:
            if lm.landmark_id == landmark_id:
                return lm
        raise KeyError(landmark_id)


def _flat_square(half_m: float, down_m: float) -> FloatArray:
    return np.array([[half_m, -half_m, down_m], [half_m, half_m, down_m],
                     [-half_m, half_m, down_m], [-half_m, -half_m, down_m]], dtype=np.float64)
