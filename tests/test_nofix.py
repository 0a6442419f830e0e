"""The diagnosis of why no fix can come (companion/nofix.py, issue 24)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from companion.nofix import NoFixWatch, WatchTimes, landmarks_in_view
from companion.pipeline.health import Blocker
from tracker.camera import CameraModel
from tracker.pose.types import AttitudeSample, MapLandmark

#: A camera looking straight down from the body (pitch -90).
DOWN = CameraModel(mount_rpy_deg=(0.0, -90.0, 0.0))
PLATE = MapLandmark("plate", (0.0, 0.0, 0.0), 2.0, 2.0, None, "other")  # flat, facing up


@dataclass
class Clock:
    now: float = 0.0

    def __call__(self) -> float:
        return self.now


@dataclass
class Item:
    value: Any


@dataclass
class Ned:
    north_m: float
    east_m: float
    down_m: float


class Link:
    def __init__(self, up: bool, position: tuple[float, float, float] | None = None) -> None:
        self.link_up = up
        self.position = position

    def latest(self, name: str) -> Item | None:
        assert name == "LOCAL_POSITION_NED"
        return None if self.position is None else Item(Ned(*self.position))


class Attitude:
    def __init__(self, clock: Clock, samples: bool) -> None:
        self.clock = clock
        self.samples = samples

    def last_us(self) -> int | None:
        return round(self.clock.now * 1e6) if self.samples else None

    def at(self, t_us: int, max_gap_us: int = 100_000) -> AttitudeSample | None:
        return AttitudeSample(t_us, 0.0, 0.0, 0.0) if self.samples else None


def watch(link: Link, clock: Clock, attitude: bool = True,
          static: Blocker | None = None) -> NoFixWatch:
    return NoFixWatch(static, link, Attitude(clock, attitude), DOWN, [PLATE], "udpout:x:1",
                      WatchTimes(grace_s=3.0, link_wait_s=3.0, attitude_wait_s=2.0,
                                 period_s=0.0), clock_s=clock)


def test_landmarks_in_view_from_above_and_beside() -> None:
    assert landmarks_in_view(DOWN, [PLATE], (0.0, 0.0, -20.0), (0.0, 0.0, 0.0)) == ["plate"]
    assert landmarks_in_view(DOWN, [PLATE], (200.0, 0.0, -20.0), (0.0, 0.0, 0.0)) == []


def test_a_link_never_up_is_named_after_the_wait_only() -> None:
    clock = Clock()
    w = watch(Link(up=False), clock)
    assert w() is None
    clock.now = 3.5
    b = w()
    assert b is not None and b.cause == "link-never-up" and "udpout:x:1" in b.detail


def test_a_link_that_was_up_is_not_never_up() -> None:
    clock, link = Clock(), Link(up=True, position=(0.0, 0.0, -20.0))
    w = watch(link, clock)
    w()
    link.link_up, clock.now = False, 10.0
    assert w() is None  # the state machine says link-down


def test_missing_attitude_is_named() -> None:
    clock = Clock()
    w = watch(Link(up=True, position=(0.0, 0.0, -20.0)), clock, attitude=False)
    clock.now = 3.5
    b = w()
    assert b is not None and b.cause == "no-attitude", b


def test_no_landmark_in_view_from_the_autopilots_position_is_named() -> None:
    clock = Clock()
    link = Link(up=True, position=(200.0, 0.0, -20.0))
    w = watch(link, clock)
    clock.now = 3.5
    b = w()
    assert b is not None and b.cause == "none-in-view" and "'plate', 201 m away" in b.detail
    link.position = (0.0, 0.0, -20.0)
    assert w() is None


def test_a_static_blocker_is_named_at_once() -> None:
    static = Blocker("no-references", "none")
    assert watch(Link(up=True), Clock(), static=static)() is static
