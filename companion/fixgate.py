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
  -- and the autopilot does not take a stream of such fixes as independent (issue 19);
* an autopilot that fuses no fix as worse than ``fused_error_cap_m`` (ArduPilot's EKF3:
  10 m) would weigh a fix stated worse as if it were that good: such a fix is sent moved
  towards the autopilot's own estimate at its time (``PoseFix.sent_position_ned_m``) by the
  ratio of the two variances, so that the update it makes is the stated fix's
  (docs/decisions.md, "A fix ArduPilot cannot weigh is sent as its pull").
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
    #: the largest horizontal 1-sigma (m) the autopilot fuses a fix with, whatever it is
    #: told (ArduPilot's EKF3: 10); 0: none (PX4 takes the variances as sent)
    fused_error_cap_m: float = field(default=0.0, metadata={"ge": 0})


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

    def stated(self, fix: PoseFix,
               autopilot_ned: tuple[float, float, float] | None = None) -> PoseFix:
        """``fix`` as the autopilot is given it: its echo stated once per correlation time
        (:meth:`_echo`), then, when that leaves it worse than ``fused_error_cap_m`` and the
        autopilot's own estimate at the fix's time (``autopilot_ned``) is known, moved
        towards that estimate by ``cap^2 / variance`` (the larger horizontal variance
        stated): an EKF that fuses it at the cap then moves by what the statement asks
        (for a prior much tighter than the cap, ``P / (P + cap^2) * g * nu ~ P / var *
        nu``).  The fix's own position and covariance are never changed."""
        fix = self._echo(fix)
        cap = self.config.fused_error_cap_m
        if cap <= 0.0 or autopilot_ned is None:
            return fix
        cov = np.asarray(fix.autopilot_covariance)
        worst = float(max(cov[0, 0], cov[1, 1]))
        if not worst > cap * cap:  # (NaN: not moved)
            return fix
        gain = cap * cap / worst if math.isfinite(worst) else 0.0
        ap = np.asarray(autopilot_ned, np.float64)
        sent = ap + gain * (np.asarray(fix.position_ned_m, np.float64) - ap)
        note = (f"sent at {gain:.3g} of its offset from the autopilot's estimate (stated "
                f"{math.sqrt(worst):.0f} m; fused at {cap:g} m at most)")
        return replace(fix, sent_position_ned_m=(float(sent[0]), float(sent[1]),
                                                 float(sent[2])),
                       notes=(*fix.notes, note))

    def _echo(self, fix: PoseFix) -> PoseFix:
        """``fix`` with ``sent_covariance``: its covariance plus
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
