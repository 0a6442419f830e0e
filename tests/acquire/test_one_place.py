"""One place, one landmark: a plate named by its appearance alone must match on every
quarter with detail, and no second landmark starts where a track already is.

The look-alikes these guard against: two map landmarks cut from overlapping parts of one
photograph (a real-imagery world flown at 11 m: real-01 and real-02 both a dock, a leaf
plant four times), whose features put the second outline on the first plate, shifted so
that one side hangs over the ground (docs/decisions.md, "One place, one landmark")."""

from __future__ import annotations

import cv2
import numpy as np

from companion.acquirers import Sighting
from companion.perception import Perception
from companion.perception_types import Occupancy, Start, Track
from tests.acquire.test_verify import scene
from tracker.acquire import ReferenceMatcher, homography_to
from tracker.boxes import box_cover, box_iou, outline_box
from tracker.camera import CameraModel
from tracker.pose.types import MapLandmark
from tracker.verify import detail_ncc, part_nccs


def covered(frame: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """``frame`` with the plate's bottom-right quarter (the quarter around its third
    corner) painted over with a smooth grey ramp: ground where the plate should be."""
    out = frame.copy()
    centre = corners.mean(axis=0)
    quarter = np.array([centre, (corners[1] + corners[2]) / 2, corners[2],
                        (corners[2] + corners[3]) / 2], np.float64)
    mask = np.zeros(frame.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, np.round(quarter).astype(np.int32), 1)
    ramp = np.tile(np.linspace(90, 130, frame.shape[1], dtype=np.float64), (frame.shape[0], 1))
    out[mask.astype(bool)] = ramp[mask.astype(bool), None].astype(np.uint8)
    return out


def perception(plate: np.ndarray) -> Perception:
    lm = MapLandmark("p", (10.0, 0.0, 0.0), 1.2, 0.8, None, "other")
    return Perception(CameraModel(320, 240, 300.0, 300.0, 159.5, 119.5), [lm], {"p": plate})


def test_each_quarter_with_detail_is_judged_on_its_own() -> None:
    frame, plate, corners = scene(noise=2.0)
    ref = ReferenceMatcher().add("p", plate)
    hom = homography_to(ref, corners)
    whole, parts = part_nccs(ref, frame, hom)
    assert whole == detail_ncc(ref, frame, hom)
    assert len(parts) == 4 and min(parts) > 0.8
    bare = covered(frame, corners)
    whole, parts = part_nccs(ref, bare, hom)
    assert whole > 0.65  # the whole still passes min_appearance_ncc ...
    assert min(parts) < 0.2 < 0.8 < sorted(parts)[1]  # ... one quarter is ground


def test_a_plate_named_by_its_look_is_refused_with_a_quarter_over_the_ground() -> None:
    frame, plate, corners = scene(noise=2.0)
    bare = covered(frame, corners)
    p = perception(plate)
    ref = p.matcher.references["p"]
    hom, box = homography_to(ref, corners), outline_box(corners)
    start, sight = p.acquisition.starter.start, Sighting(bare, Occupancy())
    assert p.config.min_part_ncc == 0.4
    for by in ("features", "detector", "search"):
        assert start("p", sight, box, hom, corners, by, []) == [], by
    # named by where the fix puts it: the place names it, a plain quarter (or one against
    # what is behind it) does not refuse it
    assert len(start("p", sight, box, hom, corners, "prediction", [])) == 1
    assert len(start("p", Sighting(frame, Occupancy()), box, hom, corners, "features",
                     [])) == 1


def test_a_second_landmark_does_not_start_where_a_track_is() -> None:
    frame, plate, corners = scene(noise=2.0)
    p = perception(plate)
    ref = p.matcher.references["p"]
    hom, box = homography_to(ref, corners), outline_box(corners)
    start = p.acquisition.starter.start
    moved = (box[0] + 0.2 * box[2], box[1], box[2], box[3])  # IoU 0.67 with box
    taken = Sighting(frame, Occupancy(frozenset({"q"}), (), (moved,)))
    assert start("p", taken, box, hom, corners, "features", []) == []
    away = (box[0] + 0.6 * box[2], box[1], box[2], box[3])  # IoU 0.25, 40 % inside: another place
    beside = Sighting(frame, Occupancy(frozenset({"q"}), (), (away,)))
    assert len(start("p", beside, box, hom, corners, "features", [])) == 1
    # a look-alike cut from the same photograph: its outline reaches past the tracked
    # plate, larger, so that the two boxes' IoU is under 0.5, yet the plate's box lies in it
    grown = (box[0] - 0.3 * box[2], box[1] - 0.3 * box[3], 1.6 * box[2], 1.6 * box[3])
    plate_box = (box[0], box[1], box[2], box[3])
    assert box_iou(grown, plate_box) < 0.5 < box_cover(grown, plate_box)
    inside = Sighting(frame, Occupancy(frozenset({"q"}), (), (grown,)))
    assert start("p", inside, box, hom, corners, "features", []) == []
    # a start of this very call holds its place too (matchers hand over the best first)
    earlier = [Start(Track("q", None, moved, hom), {})]  # type: ignore[arg-type]
    assert start("p", Sighting(frame, Occupancy()), box, hom, corners, "features",
                 earlier) == []


def test_the_snapshot_holds_the_places_of_running_and_waiting_tracks() -> None:
    frame, plate, corners = scene(noise=2.0)
    p = perception(plate)
    ref = p.matcher.references["p"]
    hom, box = homography_to(ref, corners), outline_box(corners)
    started = p.acquisition.starter.start("p", Sighting(frame, Occupancy()), box, hom,
                                          corners, "features", [])
    p.trackset.hand_over(started)
    seen = p.trackset.snapshot()
    assert seen.waiting == ("p",) and seen.places == (started[0].track.box,)
    assert seen.crowded(box)
    p.trackset.adopt()
    seen = p.trackset.snapshot()
    assert seen.tracked == frozenset({"p"}) and seen.places == (started[0].track.box,)
