"""``[landmarks]`` configuration: database, admission thresholds, practical-map selection."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class BusyZone:
    """A busy area (crowds, traffic) where no landmark is selected.

    ``lon_lat_deg`` is the polygon's outer ring as flat pairs ``[lon0, lat0, lon1, lat1,
    ...]`` (at least three vertices; closing the ring is optional).
    """

    name: str = field(default="busy zone", metadata={"min_len": 1})
    lon_lat_deg: tuple[float, ...] = field(default=(), metadata={"min_len": 6})


@dataclass(frozen=True)
class ImpactWeights:
    """Exponents of the weighted geometric mean that is the impact score."""

    distinctiveness: float = field(default=2.0, metadata={"ge": 0.0, "le": 10.0})
    flatness: float = field(default=1.0, metadata={"ge": 0.0, "le": 10.0})
    static: float = field(default=1.0, metadata={"ge": 0.0, "le": 10.0})


@dataclass(frozen=True)
class AdmissionThresholds:
    """A candidate is approved when every factor and the impact reach these minima."""

    distinctiveness_min: float = field(default=0.3, metadata={"ge": 0.0, "le": 1.0})
    flatness_min: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    static_min: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    impact_min: float = field(default=0.4, metadata={"ge": 0.0, "le": 1.0})


@dataclass(frozen=True)
class LandmarksConfig:
    """The landmark database (docs/landmarks.md explains every score)."""

    #: The on-board SQLite database (created on first use; relative to the working directory).
    db_path: str = field(default="landmarks.sqlite", metadata={"min_len": 1})
    #: A GeoJSON landmark map that ``companion run`` flies instead of the database's
    #: practical map ("" = fly the database's); the landmarks commands also fill an empty
    #: database from it.
    map_path: str = field(default="", metadata={"path": True})
    #: The area whose practical map ``run`` flies: ``bbox:MIN_LON,MIN_LAT,MAX_LON,MAX_LAT``
    #: or ``circle:LAT,LON,RADIUS_M``; "" = within ``area_radius_m`` of the EKF origin.
    area: str = ""
    area_radius_m: float = field(default=2000.0, metadata={"gt": 0.0})
    #: An EKF origin farther than this from every landmark is reported (``origin-far``).
    max_origin_distance_m: float = field(default=5000.0, metadata={"gt": 0.0})
    #: Variance ratio at which distinctiveness is 0.5: d = VR / (VR + vr_half).
    vr_half: float = field(default=1.0, metadata={"gt": 0.0})
    #: RMS distance from the best-fit plane at which flatness is 0.5.
    flatness_tolerance_m: float = field(default=0.05, metadata={"gt": 0.0})
    #: A sighting farther than this from the recorded position says "it moved".
    static_tolerance_m: float = field(default=2.0, metadata={"gt": 0.0})
    #: Sightings needed before the static score can reach 1.
    static_min_sightings: int = field(default=3, metadata={"ge": 1})
    #: Value used for a factor that is neither declared nor measurable.
    unknown_score: float = field(default=0.5, metadata={"ge": 0.0, "le": 1.0})
    weights: ImpactWeights = field(default_factory=ImpactWeights)
    thresholds: AdmissionThresholds = field(default_factory=AdmissionThresholds)
    #: Practical map: landmarks closer than this (ground distance) are not both kept.
    min_spacing_m: float = field(default=30.0, metadata={"ge": 0.0})
    #: Practical map: at most this many landmarks.
    max_count: int = field(default=50, metadata={"ge": 1})
    #: Practical map: also take landmarks still "candidate" (never "rejected").
    include_candidates: bool = False
    busy_zones: tuple[BusyZone, ...] = ()
    #: GeoJSON file of Polygon / MultiPolygon busy zones ("" = none), added to busy_zones.
    busy_zones_path: str = field(default="", metadata={"path": True})
