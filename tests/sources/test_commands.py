"""``companion synth`` and ``companion record`` as a user runs them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from companion.core.stream_format import read_meta
from companion.core.stream_io import read_truth_boxes, read_truth_range
from companion.sources.files import RecordedStreamSource

ROOT = Path(__file__).resolve().parents[2]


def companion(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "companion", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, check=False)


async def test_synth_then_record_copy(tmp_path: Path) -> None:
    out = companion("synth", "--scenario", "survey", "--out", str(tmp_path / "s"),
                    "--seconds", "0.5", "--fps", "4", "--seed", "3")
    assert out.returncode == 0, out.stderr
    assert "2 frames of scenario 'survey'" in out.stdout
    meta = read_meta(tmp_path / "s")
    assert meta.fps == 4.0 and meta.provenance["seed"] == 3
    assert read_truth_boxes(tmp_path / "s")[1] and len(read_truth_range(tmp_path / "s")) == 2
    out = companion("record", "--source", str(tmp_path / "s"), "--out", str(tmp_path / "r"))
    assert out.returncode == 0, out.stderr
    copied, original = read_truth_boxes(tmp_path / "r"), read_truth_boxes(tmp_path / "s")
    assert {k: [(b.landmark_id, b.x, b.w) for b in v] for k, v in copied.items()} == {
        k: [(b.landmark_id, b.x, b.w) for b in v] for k, v in original.items()}
    a = RecordedStreamSource(tmp_path / "s", realtime=False)
    b = RecordedStreamSource(tmp_path / "r", realtime=False)
    for _ in range(2):
        fa, fb = await a.recv(), await b.recv()
        assert fa.t_us == fb.t_us and np.array_equal(fa.image, fb.image)


def test_record_sim_with_truth_and_frame_limit(tmp_path: Path) -> None:
    out = companion("record", "--source", "sim:hover", "--out", str(tmp_path / "r"),
                    "--frames", "2")
    assert out.returncode == 0, out.stderr
    assert sorted(read_truth_boxes(tmp_path / "r")) == [0, 1]


def test_bad_input_is_one_line(tmp_path: Path) -> None:
    out = companion("synth", "--scenario", "nope", "--out", str(tmp_path / "x"))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert "no such scenario" in out.stderr
    out = companion("record", "--source", "stream:" + str(tmp_path / "missing"),
                    "--out", str(tmp_path / "y"))
    assert out.returncode == 2 and "stream folder does not exist" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    out = companion("record", "--source", "/dev/video-none", "--out", str(tmp_path / "z"))
    assert out.returncode == 1 and "cannot open" in out.stderr
