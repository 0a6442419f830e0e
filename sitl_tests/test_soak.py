"""The soak's short form for CI: 75 s of ``companion run`` watched for leaks.

The long form (30 minutes, documented in docs/reliability.md) is ``benchmarks/soak.py``;
both run :func:`testsupport.soak.soak` and apply the same checks (``verdict``).
"""

from __future__ import annotations

from pathlib import Path

import cv2

from testsupport.soak import plot, soak

#: The picture of the last short soak (test-output/ is ignored by git).
PICTURE = Path(__file__).resolve().parents[1] / "test-output" / "soak-short.png"


async def test_soak_short(tmp_path: Path) -> None:
    """75 s of flight after start-up: after a 30 s warm-up resident memory grows <= 5 % (the
    floor between transients, and the peak against the first third's), file descriptors do
    not grow, threads by at most one (a pool thread started late), every 3 s interval has
    fused fixes and the rate does not trend down (second half's median >= 70 % of the
    first's); the process then exits 0 by itself.

    The warm-up is 30 s, not 15: on a quiet or a busy development machine the process
    reaches its level by 9-15 s, but one CI run found it 12 MB lower at 15 s and at that
    level at 45 s (docs/reliability.md, 'The short soak's warm-up')."""
    result = await soak(75.0, sample_s=3.0, tmp=tmp_path, thread_slack=1, warm_up_s=30.0)
    v = result["verdict"]
    print("soak (short):", v)
    print("samples (t s, RSS floor MB, RSS peak MB, fds, threads, fused):",
          [(s["t_s"], s["rss_mb"], s["rss_peak_mb"], s["fds"], s["threads"], s["fused"])
           for s in result["samples"]])
    PICTURE.parent.mkdir(exist_ok=True)
    if result["samples"]:
        cv2.imwrite(str(PICTURE), plot(result))
        print("memory over the flight:", PICTURE)
    assert result["exit_status"] == 0, result["stderr_tail"]
    assert len(result["samples"]) >= 12, "the flight did not last"
    assert v["fused_per_interval"]["median"] > 0, "no fixes: nothing was soaked"
    assert v["ok"], v
