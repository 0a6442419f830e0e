"""A cut plate's outline must hold its tracker's box (issue 19's square: leaving (6, 6),
sign-01 cut by the bottom edge was aligned 120-150 px beside the box its tracker held, the
box centre 50 px outside the outline for half a second, and the fixes from those corners
were 1.1-1.8 m off).  A whole plate's alignment is held to its box already; a cut one's
affine alignment on the part in view is now too."""

from __future__ import annotations

import cv2
import numpy as np

from companion.corners import Corners
from companion.perception_types import Track
from tests.plates import plate_track, textured_plate


def scene() -> tuple[Corners, Track, np.ndarray, np.ndarray]:
    """A textured 240x160 plate at (200, 400), cut by the image's bottom edge (80 of its
    160 rows in view); a track on it whose tracker box holds the part in view."""
    grey, matcher, ref = textured_plate(5)
    image = np.full((480, 640, 3), 90, np.uint8)
    plate = cv2.resize(grey, (240, 160))
    image[400:480, 200:440] = cv2.merge([plate, plate, plate])[:80]
    corners, track, truth = plate_track(image, matcher, ref, (200.0, 400.0, 240.0, 160.0),
                                        (200.0, 400.0, 240.0, 80.0))
    return corners, track, image, truth


def test_a_cut_outline_beside_its_box_gives_no_corners() -> None:
    corners, track, image, truth = scene()
    beside = truth.copy()
    beside[0, 2] += 250.0  # the alignment ran 250 px right: the box centre (320, 440) is out
    corners.align_cut = lambda *_args, **_kw: beside  # type: ignore[method-assign]
    corners.follow(track, image, track.box)
    assert track.corners is None and track.disputed
    np.testing.assert_array_equal(track.homography, truth)  # kept: tried again next frame
    assert track.box == (200.0, 400.0, 240.0, 80.0)
    # 60 px off, the box centre still on the outline: taken (the rule is for a runaway)
    near = truth.copy()
    near[0, 2] += 60.0
    corners.align_cut = lambda *_args, **_kw: near  # type: ignore[method-assign]
    corners.follow(track, image, track.box)
    assert track.corners is not None and not track.disputed
