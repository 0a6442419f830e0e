"""The flight map's acquisition report: why each landmark cannot be acquired (issue 24)."""

from __future__ import annotations

import cv2
import numpy as np

from companion.core.landmark import Appearance, Landmark
from companion.flightmap import PracticalMap, acquisition_report, reference_image
from companion.landmarks.geodesy import LocalFrame
from companion.perception import Perception
from tracker.camera import CameraModel
from tracker.pose.types import MapLandmark


def png(image: np.ndarray) -> bytes:
    return cv2.imencode(".png", image)[1].tobytes()


def landmark(lid: str, appearance: Appearance | None) -> Landmark:
    return Landmark(lid, lid, "other", 47.0, 8.0, 400.0, 1.0, 1.0, appearance=appearance)


def textured(size: int) -> np.ndarray:
    rng = np.random.default_rng(size)
    return cv2.resize(rng.integers(0, 255, (size // 8 + 1, size // 8 + 1, 3), np.uint8),
                      (size, size), interpolation=cv2.INTER_NEAREST)


def test_each_landmark_that_cannot_be_acquired_has_its_reason() -> None:
    records = [
        landmark("good", Appearance("image/png", png(textured(200)))),
        landmark("none", None),
        landmark("garbage", Appearance("image/png", b"not an image")),
        landmark("outside", Appearance("image/png", png(textured(64)), (500, 500, 10, 10))),
        landmark("blank", Appearance("image/png", png(np.full((80, 80, 3), 128, np.uint8)))),
        landmark("tiny", Appearance("image/png", png(textured(16)))),
    ]
    references, unusable = {}, {}
    for lm in records:
        image, why = reference_image(lm)
        if image is None:
            unusable[lm.id] = str(why)
        else:
            references[lm.id] = image
    pmap = PracticalMap(tuple(MapLandmark(lm.id, (0.0, 0.0, 0.0), 1.0, 1.0, None, "other")
                              for lm in records), references, LocalFrame(47.0, 8.0),
                        unusable, described="test")
    perception = Perception(CameraModel(), pmap.landmarks, references)
    try:
        report = acquisition_report(pmap, perception)
    finally:
        perception.close()
    assert report["with_reference"] == ["good", "tiny"]
    cannot = report["cannot_acquire"]
    assert set(cannot) == {"none", "garbage", "outside", "blank"}
    assert cannot["none"].startswith("no appearance image")
    assert cannot["garbage"].startswith("appearance image unreadable (image/png, 12 bytes)")
    assert cannot["outside"] == "appearance_box [500, 500, 10, 10] lies outside the image"
    assert "blank" in cannot["blank"]
    assert report["weak"]["tiny"].startswith("too small (16x16 px, under 24 px a side)")
