"""The real-imagery world (issue 25): real photographs as ground and landmarks, a stream
with truth, the light script, and a different world per seed."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.cli import main
from companion.core.map_file import read_map
from companion.core.stream_io import read_truth
from companion.sim.effects import EffectSpec, EffectStack, vignette_gain
from companion.sim.realworld import RealWorldSpec, shared_data, synth_real
from companion.sim.world import World, WorldConfig

DATA = shared_data()


def need_data() -> None:
    if not (DATA / "aerial").is_dir() or not (DATA / "otb").is_dir():
        pytest.skip(f"real photographs not available at {DATA} (set LMC_SHARED_DATA)")


def small(seed: int) -> RealWorldSpec:
    return RealWorldSpec(seed=seed, seconds=16.0, fps=2.0)


def test_the_world_is_real_photographs_with_truth_and_appearance_images(tmp_path: Path) -> None:
    need_data()
    sim, count = synth_real(small(0), tmp_path / "s")
    assert count == 32
    records = read_map(tmp_path / "s" / "landmarks.geojson")
    assert len(records) == 6 and all(r.facing_deg is None for r in records)
    # each landmark's appearance image is the texture the frames show: a real crop
    for rec, lm in zip(records, sim.world.landmarks, strict=True):
        assert rec.appearance is not None
        img = cv2.imdecode(np.frombuffer(rec.appearance.data, np.uint8), cv2.IMREAD_COLOR)
        assert lm.quad.texture is not None and np.array_equal(img, lm.quad.texture)
    # the ground is the aerial photograph, not the generated texture
    ground = sim.world.ground.texture
    photos = [cv2.imread(str(p)) for p in sorted((DATA / "aerial").glob("*.jpg"))]
    assert ground is not None
    assert any(p.shape == ground.shape and np.array_equal(p, ground) for p in photos)
    truth = read_truth(tmp_path / "s")
    full = [sum(b.in_view_frac >= 1.0 for b in t.boxes) for t in truth.values()]
    assert np.mean([n >= 2 for n in full]) > 0.8  # two or more plates wholly in view
    assert all(abs(t.pose.down_m + 17.0) < 0.5 for t in truth.values())
    frames = sorted((tmp_path / "s" / "frames").iterdir())
    assert frames[0].suffix == ".jpg"


def test_the_light_ramps_down_steps_up_and_turns_warm(tmp_path: Path) -> None:
    need_data()
    spec = small(1)
    synth_real(spec, tmp_path / "s")
    frames = sorted((tmp_path / "s" / "frames").iterdir())
    mean = [cv2.imread(str(f)).reshape(-1, 3).mean(axis=0) for f in frames]
    before, after = mean[int(11.5 * spec.fps)], mean[int(12.0 * spec.fps)]
    assert 1.9 < after.sum() / before.sum() < 2.6  # step from 55 % to 125 %
    assert mean[int(11.5 * spec.fps)].sum() < 0.7 * mean[0].sum()  # the ramp down
    warm, cool = mean[int(15.5 * spec.fps)], mean[int(14.5 * spec.fps)]
    assert warm[2] / warm[0] > 1.2 * cool[2] / cool[0]  # red over blue rises from 15 s


def test_each_seed_is_another_world(tmp_path: Path) -> None:
    need_data()
    synth_real(small(0), tmp_path / "a")
    synth_real(small(3), tmp_path / "b")
    a, b = (read_map(tmp_path / n / "landmarks.geojson") for n in "ab")
    assert [r.appearance.data for r in a if r.appearance] != \
        [r.appearance.data for r in b if r.appearance]
    assert [(r.lat_deg, r.lon_deg) for r in a] != [(r.lat_deg, r.lon_deg) for r in b]


def test_synth_world_real_from_the_command_line_with_explicit_crops(tmp_path: Path) -> None:
    need_data()
    src = sorted((DATA / "otb").glob("*/img/0001.jpg"))[:2]
    out = tmp_path / "s"
    rc = main(["synth", "--world", "real", "--out", str(out), "--seconds", "2", "--fps", "2",
               *[a for p in src for a in ("--crop", f"{p}:10,20,80,60")]])
    assert rc == 0
    records = read_map(out / "landmarks.geojson")
    assert len(records) == 2
    img = cv2.imdecode(np.frombuffer(records[0].appearance.data, np.uint8),  # type: ignore[union-attr]
                       cv2.IMREAD_COLOR)
    assert np.array_equal(img, cv2.imread(str(src[0]))[20:80, 10:90])


def test_vignetting_darkens_the_corners_not_the_centre() -> None:
    gain = vignette_gain((48, 64, 3), 0.35)
    assert gain[24, 32, 0] == pytest.approx(1.0, abs=0.01)
    assert gain[0, 0, 0] == pytest.approx(0.65, abs=0.01)
    world = World([], WorldConfig(ground_texture_px=64))
    stack = EffectStack((EffectSpec("vignette", strength=0.35),), world, 0)
    out = stack.apply(np.full((48, 64, 3), 200, np.uint8), 0.0, 0, ())
    assert out[24, 32, 0] >= 198 and out[0, 0, 0] <= 132

