"""companion.fixgate: a fix too vague for its distance is held back (issue 25)."""

from __future__ import annotations

import numpy as np

from companion.fixgate import FixGate, FixGateConfig
from tracker.pose.types import PoseFix


def fix(sigma_m: float) -> PoseFix:
    cov = np.diag([sigma_m**2 / 3] * 3 + [1e-4] * 3)
    return PoseFix(0, (0.0, 0.0, -17.0), (0.0, 0.0, 0.0), cov, 80, ("a",), "pnp")


def test_a_fix_whose_sigma_exceeds_its_share_of_the_distance_is_not_precise() -> None:
    gate = FixGate(FixGateConfig(max_sigma_rel=0.05))
    assert gate.precise(fix(0.9), 20.0)  # 4.5 % of 20 m
    assert not gate.precise(fix(1.1), 20.0)  # 5.5 %
    assert not gate.precise(fix(0.1), 0.0)  # no distance: nothing is precise enough


def test_the_vagueness_check_is_off_by_default() -> None:
    assert FixGate().precise(fix(100.0), 1.0)
