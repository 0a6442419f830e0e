"""A lone plate's fix takes the learnt attitude at the lone floors
(``pose.attitude_bias_lone_floor_*``; docs/decisions.md, "The learnt attitude's floor for a
lone plate"): ``Perception._solve`` decides it by the observations with corners, as
``CornerNoise.alone`` does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion import perception as perception_module
from companion.core.frames import Frame
from companion.perception import Perception
from companion.perception_types import Track
from companion.side_sensors import SideSensors
from tests.pose.conftest import TRUE_P, TRUE_RPY, wall
from tracker.camera import CameraModel
from tracker.pose.config import PoseConfig
from tracker.pose.types import AttitudeSample, NoFix, Observation, PoseFix

LANDMARKS = list(wall()[:2])
CONFIG = PoseConfig(learn_attitude_bias=True, attitude_bias_lone_floor_rp_deg=0.1,
                    attitude_bias_lone_floor_yaw_deg=0.15)


def read(t_us: int) -> SideSensors:
    return SideSensors(attitude=AttitudeSample(t_us, *TRUE_RPY, math.radians(2.5),
                                               math.radians(5.0)))


def obs(lid: str, corners: bool = True) -> Observation:
    px = ((300.0, 200.0), (340.0, 200.0), (340.0, 230.0), (300.0, 230.0))
    return Observation(centre_px=(320.0, 215.0), box_wh_px=(40.0, 30.0), landmark_id=lid,
                       corners_px=px if corners else None,
                       corner_sigma_px=0.2 if corners else None)


@pytest.mark.parametrize(("seen", "rp_deg", "yaw_deg"), [
    ((("A", True),), 0.1, 0.15),  # one plate: the lone floors
    ((("A", True), ("B", False)), 0.1, 0.15),  # beside a box only: still alone
    ((("A", True), ("B", True)), 0.2, 0.5),  # two plates: the floors
])
def test_the_prior_of_a_lone_plate_takes_the_lone_floors(
        monkeypatch: pytest.MonkeyPatch, seen: tuple[tuple[str, bool], ...],
        rp_deg: float, yaw_deg: float) -> None:
    p = Perception(CameraModel(), LANDMARKS, {}, sensors=read, pose_config=CONFIG)
    assert p.side.bias is not None
    cov = np.diag([0.01, 0.01, 0.01, *np.radians([0.01, 0.01, 0.01]) ** 2])
    p.side.bias.learn(read(0).attitude, PoseFix(0, tuple(TRUE_P), TRUE_RPY, cov, 90,
                                                ("A", "B"), "bearing_ls", attitude_prior="used"))
    for lid, _ in seen:
        p.trackset.live[lid] = Track(lid, None,  # type: ignore[arg-type]
                                     (300.0, 200.0, 40.0, 30.0), None)
    monkeypatch.setattr(p, "observations", lambda _i: [obs(lid, c) for lid, c in seen])
    monkeypatch.setattr(p.trackset, "particles", dict)  # no trackers behind these tracks
    given: list[AttitudeSample | None] = []

    def solve(*_a: object, attitude: AttitudeSample | None = None, **_k: object) -> NoFix:
        given.append(attitude)
        return NoFix(0, "recorded")

    monkeypatch.setattr(perception_module, "solve_pose", solve)
    p._solve(Frame(1, 0, np.zeros((480, 640, 3), np.uint8), "cam"), [])
    (att,) = given
    assert att is not None
    assert math.degrees(att.roll_pitch_sigma_rad) == pytest.approx(rp_deg)
    assert math.degrees(att.yaw_sigma_rad) == pytest.approx(yaw_deg)


def test_without_the_learner_a_lone_plate_takes_the_attitude_as_read() -> None:
    p = Perception(CameraModel(), LANDMARKS, {}, sensors=read,
                   pose_config=dataclasses.replace(CONFIG, learn_attitude_bias=False))
    assert p.side.for_lone_plate(read(0), read(0)) == read(0)
