"""The preview shows what the companion sees: boxes, corners, particles, ids."""

from __future__ import annotations

import cv2
import numpy as np

from companion.preview import render_preview


def test_preview_is_a_downscaled_jpeg_with_the_tracks_drawn() -> None:
    frame = np.full((480, 640, 3), 60, np.uint8)
    track = {"landmark_id": "wall-01", "confidence": 0.9, "box": [100, 100, 200, 100],
             "corners": [[110, 110], [290, 110], [290, 190], [110, 190]],
             "particles": np.array([[400.0, 300.0], [420.0, 320.0]])}
    jpeg = render_preview(frame, [track], width_px=320, quality=90, caption="fix")
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (240, 320, 3)  # half size
    green = image[50, 75]  # the box's top edge at (100..300, 100) / 2
    assert green[1] > 150 and green[2] < 150
    yellow = image[55, 100]  # the corners' top edge at y = 110 / 2
    assert yellow[1] > 150 and yellow[2] > 150 and int(yellow[2]) - int(yellow[0]) > 60
    cyan = image[150, 200]  # a particle at (400, 300) / 2
    assert cyan[0] > 150 and cyan[1] > 150
    untouched = image[200, 40]
    assert abs(int(untouched[0]) - 60) < 12  # nothing drawn there


def test_empty_tracks_give_the_plain_frame() -> None:
    frame = np.full((100, 200, 3), 128, np.uint8)
    image = cv2.imdecode(np.frombuffer(render_preview(frame, [], 400, 90), np.uint8),
                         cv2.IMREAD_COLOR)
    assert image.shape == (100, 200, 3)  # never scaled up
    assert abs(int(image.mean()) - 128) <= 2
