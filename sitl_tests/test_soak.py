"""The soak's short form for CI: 45 s of ``companion run`` watched for leaks.

The long form (30 minutes, documented in docs/reliability.md) is ``benchmarks/soak.py``;
both run :func:`testsupport.soak.soak` and apply the same checks (``verdict``).
"""

from __future__ import annotations

from pathlib import Path

from testsupport.soak import soak


async def test_soak_short(tmp_path: Path) -> None:
    """45 s of flight after start-up: after a 15 s warm-up resident memory grows <= 5 %,
    file descriptors do not grow, threads by at most one (a pool thread started late), every
    3 s interval has fused fixes and the rate does not trend down (second half's median
    >= 70 % of the first's); the process then exits 0 by itself."""
    result = await soak(45.0, sample_s=3.0, tmp=tmp_path, thread_slack=1)
    v = result["verdict"]
    print("soak (short):", v)
    assert result["exit_status"] == 0, result["stderr_tail"]
    assert len(result["samples"]) >= 12, "the flight did not last"
    assert v["fused_per_interval"]["median"] > 0, "no fixes: nothing was soaked"
    assert v["ok"], v
