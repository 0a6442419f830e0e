"""The companion's health: one state, recomputed from what the pipeline observes.

States (priority order when several apply):

* ``starting``   -- nothing processed yet;
* ``link-down``  -- no heartbeat from the autopilot within the link timeout;
* ``degraded``   -- the camera stalled (no frame within the stall timeout) or most recent
  frames were unreadable;
* ``tracking``   -- at least one landmark tracked and a fix computed recently;
* ``lost``       -- landmarks were tracked before but none for ``lost_after_s``;
* ``searching``  -- frames flow, nothing acquired yet.

Above all of them, ``blocked``: no fix came recently *and* a reason is known why none can
come (a :class:`Blocker`: ``no-landmarks``, ``no-references``, ``origin-far``,
``link-never-up``, ``no-attitude``, ``none-in-view``; docs/monitoring.md).  A fix that
does come ends it, whatever the diagnosis said.

The heartbeat's MAV_STATE and the monitor's status follow this state; every change is an
event.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

State = Literal["starting", "searching", "tracking", "degraded", "lost", "link-down",
                "blocked"]


@dataclass(frozen=True)
class Blocker:
    """A named reason why no fix can come, and the details a user needs to fix it."""

    cause: str
    detail: str

    def as_dict(self) -> dict[str, str]:
        return {"cause": self.cause, "detail": self.detail}


@dataclass(frozen=True)
class HealthInputs:
    """What the pipeline knows at one instant (times on the companion clock, seconds)."""

    now_s: float
    frames_processed: int
    last_frame_s: float | None
    last_fix_s: float | None
    ever_tracked: bool
    link_up: bool
    bad_frame_ratio: float = 0.0
    blocker: Blocker | None = None


@dataclass(frozen=True)
class HealthPolicy:
    """Thresholds of the state machine."""

    stall_after_s: float = 1.0
    fix_fresh_s: float = 0.5
    lost_after_s: float = 1.0
    bad_frame_ratio_degraded: float = 0.5


def health_state(i: HealthInputs, policy: HealthPolicy = HealthPolicy()) -> State:
    """The state for inputs ``i`` (pure, so every transition is unit-testable)."""
    fresh = i.last_fix_s is not None and i.now_s - i.last_fix_s <= policy.fix_fresh_s
    if i.blocker is not None and not fresh:
        return "blocked"
    if i.frames_processed == 0 and i.last_frame_s is None:
        return "starting"
    if not i.link_up:
        return "link-down"
    stalled = i.last_frame_s is None or i.now_s - i.last_frame_s > policy.stall_after_s
    if stalled or i.bad_frame_ratio >= policy.bad_frame_ratio_degraded:
        return "degraded"
    if fresh:
        return "tracking"
    if i.ever_tracked and (i.last_fix_s is None or i.now_s - i.last_fix_s > policy.lost_after_s):
        return "lost"
    if i.ever_tracked:
        return "tracking"
    return "searching"
