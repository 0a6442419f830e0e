"""The replay's "track on a wrong place" score (companion/replay_score.py, issue 25)."""

from __future__ import annotations

import pytest

from companion.replay_score import in_image, on_its_landmark
from tracker.camera import CameraModel

CAMERA = CameraModel()  # 640 x 480


def test_a_track_following_its_plate_out_of_the_image_is_on_its_landmark() -> None:
    # real world seed 1, frame 592: the plate leaves at the bottom; its true box is cut to
    # the image, the tracker's box reaches 44 px past the edge
    true = (377.0, 463.0, 79.0, 16.0)
    box = (377.0, 434.0, 77.0, 93.0)
    assert in_image(box, CAMERA) == (377.0, 434.0, 77.0, 45.0)
    assert on_its_landmark(box, true, CAMERA)


def test_a_track_off_its_plate_or_with_its_plate_out_of_view_is_on_a_wrong_place() -> None:
    true = (377.0, 463.0, 79.0, 16.0)
    assert not on_its_landmark((100.0, 100.0, 50.0, 50.0), true, CAMERA)
    # a sliver left in view, the tracker's box 50 px above it: wrong, cut or not
    assert not on_its_landmark((375.0, 425.0, 69.0, 111.0), (375.0, 476.0, 80.0, 3.0), CAMERA)
    assert not on_its_landmark((377.0, 434.0, 77.0, 93.0), None, CAMERA)
    assert not on_its_landmark((700.0, 100.0, 50.0, 50.0), true, CAMERA)  # all outside


@pytest.mark.parametrize("box", [(-20.0, -10.0, 40.0, 30.0), (630.0, 470.0, 40.0, 40.0)])
def test_the_part_in_the_image_is_cut_as_the_true_box_is(box: tuple[float, ...]) -> None:
    x, y, w, h = in_image(box, CAMERA) or (0.0, 0.0, 0.0, 0.0)
    assert x >= 0 and y >= 0 and x + w <= 639 and y + h <= 479 and w > 0 and h > 0
