"""The perception's fingerprint, for refactors that must not change a fix (issue 21).

Survey frames 0-299 and street frames 0-199 through :func:`tests.test_perception.flight`
(the true attitude, housekeeping after every frame: repeatable), and a sha256 over every
fix's frame index and position (rounded to 1e-9 m)::

    .venv/bin/python -m tests.perception_fingerprint      # e.g. "fixes 494 sha256 9ccd3dab"

The same output before and after a change, on one machine, means the same fixes (the hash
differs between machines: docs/testing.md).  Not a test (pytest
collects ``test_*.py`` only); it lives here because it runs the tests' own flight.
"""

from __future__ import annotations

import hashlib

from tests.test_perception import flight
from tracker.pose.types import PoseFix


def fingerprint() -> str:
    digest, count = hashlib.sha256(), 0
    for scenario, frames in (("survey", range(0, 300)), ("street", range(0, 200))):
        _, _, out = flight(scenario, frames)
        for result, _, _ in out:
            fix = result.fix
            if isinstance(fix, PoseFix):
                count += 1
                position = tuple(round(float(v), 9) for v in fix.position_ned_m)
                digest.update(repr((result.frame_index, position)).encode())
    return f"fixes {count} sha256 {digest.hexdigest()[:8]}"


if __name__ == "__main__":
    print(fingerprint())
