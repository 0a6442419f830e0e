"""Temporal consistency of fixes: never pass on an invented jump.

A single-landmark solution can flip to its mirror image (the planar two-fold ambiguity)
or a track can latch onto the wrong thing for a frame.  The gate compares each fix with
the last one it let through:

* while fixes keep coming (gap <= ``max_gap_s``) a fix must lie within
  ``max_speed_m_s * dt + n_sigma * sigma + slack_m`` of the previous one, else it is held
  back and counted;
* after a gap (start, a loss, a run of rejections) it needs ``confirm`` fixes in a row
  that agree with each other before any is passed on, so a wrong first fix cannot lock
  the gate onto itself;
* a fix whose own position 1-sigma exceeds ``max_sigma_rel`` of the distance to the
  landmarks it used is not passed on: too vague to help, and on real imagery such fixes
  (one plate, seen small) were the ones whose covariance was not honest (issue 25);
* :meth:`FixGate.stated` gives the covariance a passed fix is sent with (``PoseFix.
  sent_covariance``; its own ``covariance`` is kept): the part that the
  autopilot's own attitude and height carry (``PoseFix.echo_covariance``) is the
  autopilot's error coming back, the same in every fix while it lasts, so it is stated
  as one fix per ``echo_correlation_s`` would state it -- times that many fixes' intervals
  -- and the autopilot does not take a stream of such fixes as independent (issue 19).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from tracker.pose.types import PoseFix


@dataclass(frozen=True)
class FixGateConfig:
    """Thresholds of the temporal gate."""

    max_speed_m_s: float = field(default=15.0, metadata={"gt": 0})
    n_sigma: float = field(default=5.0, metadata={"gt": 0})
    slack_m: float = field(default=0.3, metadata={"ge": 0})
    max_gap_s: float = field(default=1.0, metadata={"gt": 0})
    confirm: int = field(default=3, metadata={"ge": 1})
    max_sigma_rel: float = field(default=0.0, metadata={"ge": 0})  # 0: off
    #: how long the autopilot's attitude and height errors last (s; 0: fixes are stated
    #: as solved, each as if independent)
    echo_correlation_s: float = field(default=0.0, metadata={"ge": 0})


@dataclass
class FixGate:
    """Stateful gate; :meth:`admit` says whether a fix may go to the autopilot."""

    config: FixGateConfig = field(default_factory=FixGateConfig)
    rejected: int = 0
    _last: PoseFix | None = None
    _candidates: list[PoseFix] = field(default_factory=list)
    _last_stated_us: int | None = None

    def _consistent(self, a: PoseFix, b: PoseFix) -> bool:
        cfg = self.config
        dt = abs(b.time_us - a.time_us) / 1e6
        sigma = math.sqrt(float(np.trace(np.asarray(a.covariance)[:3, :3]))
                          + float(np.trace(np.asarray(b.covariance)[:3, :3])))
        limit = cfg.max_speed_m_s * dt + cfg.n_sigma * sigma + cfg.slack_m
        return math.dist(a.position_ned_m, b.position_ned_m) <= limit

    def precise(self, fix: PoseFix, distance_m: float) -> bool:
        """The fix's position 1-sigma is at most ``max_sigma_rel`` of ``distance_m``
        (always, when ``max_sigma_rel`` is 0)."""
        if self.config.max_sigma_rel <= 0.0:
            return True
        sigma = math.sqrt(float(np.trace(np.asarray(fix.covariance)[:3, :3])))
        return sigma <= self.config.max_sigma_rel * distance_m

    def admit(self, fix: PoseFix) -> bool:
        """True when ``fix`` is consistent with the recent ones."""
        last = self._last
        if last is not None and (fix.time_us - last.time_us) / 1e6 <= self.config.max_gap_s:
            if self._consistent(last, fix):
                self._last = fix
                return True
            self.rejected += 1
            return False
        # after a gap: collect agreeing candidates before trusting any
        self._candidates = [c for c in self._candidates if self._consistent(c, fix)
                            and (fix.time_us - c.time_us) / 1e6 <= self.config.max_gap_s]
        self._candidates.append(fix)
        if len(self._candidates) >= self.config.confirm:
            self._candidates.clear()
            self._last = fix
            return True
        self.rejected += 1
        return False

    def stated(self, fix: PoseFix) -> PoseFix:
        """``fix`` with ``sent_covariance``, what the autopilot is given: its covariance plus
        ``n - 1`` times the part the autopilot's own attitude and height carry, ``n`` =
        ``echo_correlation_s`` over the time since the previous fix passed on (at least 1: a
        fix after a longer pause is sent as solved).  Over a correlation time the stream
        then carries that part's information once, as the errors do.  Unchanged when
        ``echo_correlation_s`` is 0 or the fix has no such part; ``covariance`` (the fix's
        own, for its NEES and the reports) is never changed."""
        last, self._last_stated_us = self._last_stated_us, fix.time_us
        tau = self.config.echo_correlation_s
        if tau <= 0.0 or fix.echo_covariance is None or last is None:
            return fix
        dt = (fix.time_us - last) / 1e6
        n = tau / dt if dt > 0.0 else 1.0
        if n <= 1.0:
            return fix
        cov = np.asarray(fix.covariance) + (n - 1.0) * np.asarray(fix.echo_covariance)
        note = f"the autopilot's attitude and height part stated x {n:.0f} (time-correlated)"
        return replace(fix, sent_covariance=cov, notes=(*fix.notes, note))
