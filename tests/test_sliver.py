"""An outline squashed to a sliver is no plate in view (issue 19's square, seed 3 of a
real-time round: a plate entering at the image's right edge was aligned onto a 7 px wide
sliver, its tracker re-seated on that sliver's box, and the box-only fix from it was 2.2 m
off).  The geometry of the limit, and a track's corners refusing such an alignment."""

from __future__ import annotations

import cv2
import numpy as np

from companion.corners import Corners
from companion.perception_types import Track
from tests.plates import plate_track, textured_plate
from tracker.boxes import aspect_change, squashed


def seen_turned(angle_deg: float, width_m: float = 1.2, height_m: float = 0.9) -> np.ndarray:
    """The outline (TL, TR, BR, BL, px) of a plate 4 m ahead, turned ``angle_deg`` about
    its vertical axis, through a 525 px pinhole."""
    a = np.radians(angle_deg)
    xs = np.array([-1, 1, 1, -1]) * width_m / 2
    ys = np.array([-1, -1, 1, 1]) * height_m / 2
    x, z = xs * np.cos(a), 4.0 + xs * np.sin(a)
    return np.stack([320 + 525 * x / z, 240 + 525 * ys / z], axis=1)


def test_a_plate_turned_75_deg_is_a_plate_at_85_deg_a_sliver() -> None:
    assert aspect_change(seen_turned(0.0), (1.2, 0.9)) < 1.01
    assert not squashed(seen_turned(60.0), (1.2, 0.9))
    assert not squashed(seen_turned(75.0), (1.2, 0.9))
    assert squashed(seen_turned(85.0), (1.2, 0.9))
    # a plate 0.9 wide and 1.2 tall turned about its horizontal axis (the image
    # transposed, the corners kept TL, TR, BR, BL): its own aspect is taken out
    def tipped(angle_deg: float) -> np.ndarray:
        return seen_turned(angle_deg)[[0, 3, 2, 1]][:, ::-1]
    assert squashed(tipped(85.0), (0.9, 1.2))
    assert not squashed(tipped(75.0), (0.9, 1.2))


def scene() -> tuple[Corners, Track, np.ndarray, np.ndarray]:
    """A textured 120x80 plate at (500, 200); a track on it whose tracker box holds the
    part that was in view when it was acquired (``partial_box``)."""
    grey, matcher, ref = textured_plate(5)
    image = np.full((480, 640, 3), 90, np.uint8)
    image[200:280, 500:620] = cv2.merge([grey, grey, grey])
    corners, track, truth = plate_track(image, matcher, ref, (500.0, 200.0, 120.0, 80.0),
                                        (560.0, 200.0, 60.0, 80.0))
    return corners, track, image, truth


def test_an_alignment_onto_a_sliver_gives_no_corners_and_no_box() -> None:
    corners, track, image, truth = scene()
    # the alignment runs away onto the plate's right edge: 6 px wide, as tall as the plate
    ref = corners.references["plate"]
    sliver = np.array([[6 / ref.size_px[0], 0.0, 612.0], [0.0, truth[1, 1], 200.0],
                       [0.0, 0.0, 1.0]])
    corners.align = lambda *_args, **_kw: sliver  # type: ignore[method-assign]
    corners.follow(track, image, track.box)
    assert track.corners is None and track.disputed
    np.testing.assert_array_equal(track.homography, truth)  # kept: tried again next frame
    assert track.box == (560.0, 200.0, 60.0, 80.0)  # not re-seated on the sliver's box
    assert track.misses == 1
    # the plate's own outline, aligned, is taken (and its tracker re-seated on it)
    corners.align = lambda *_args, **_kw: truth  # type: ignore[method-assign]
    corners.follow(track, image, track.box)
    assert track.corners is not None and not track.disputed
    assert abs(track.box[2] - 120.0) < 1.0
