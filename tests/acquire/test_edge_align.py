"""A plate cut by the image's edge keeps its homography (tracker/edge_align.py, issue 19).

A full homography aligned on the corner of a plate still in view bends the corners
outside; the affine move of the last homography keeps them, and holds the corner inside.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.acquire import ReferenceMatcher, homography_to, project_corners, refine_ecc
from tracker.edge_align import (
    MAX_LINEAR_STEP,
    SLIVER_PIXELS,
    align_cut,
    box_shift,
    search_shift,
    shifted,
)

from .test_acquire import place, textured_poster


def _frames(seed: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """A 256x170 poster drawn 300x200 px with only its top-left part in the image (about
    a sixth of it), moving 1.5 px left and up (and growing 0.5 %) a frame for 12 frames."""
    rng = np.random.default_rng(seed)
    start = np.array([[540.0, 390.0], [840.0, 396.0], [836.0, 596.0], [544.0, 590.0]])
    start += rng.uniform(-5, 5, (4, 2))
    out = []
    for k in range(12):
        centre = start.mean(axis=0)
        out.append(centre + (start - centre) * (1.0 + 0.005 * k) - 1.5 * k)
    return start, out


def test_a_cut_plate_holds_its_corners_where_a_full_alignment_bends_them() -> None:
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    for seed in range(3):
        _, truths = _frames(seed)
        hom_cut = hom_full = homography_to(ref, truths[0])
        err_cut, err_full = [], []
        for k, truth in enumerate(truths[1:], start=1):
            gray = cv2.cvtColor(place(poster, truth, seed=seed + k), cv2.COLOR_BGR2GRAY)
            moved = align_cut(ref, gray, hom_cut)
            assert moved is not None, (seed, k)
            hom_cut = moved
            full = refine_ecc(ref, gray, hom_full)
            hom_full = hom_full if full is None else full
            err_cut.append(np.abs(project_corners(ref, hom_cut) - truth).max(axis=1))
            err_full.append(np.abs(project_corners(ref, hom_full) - truth).max(axis=1))
        inside = np.array(err_cut)[:, 0]  # the top-left corner, in the image
        print(f"seed {seed}: cut: inside corner {inside.max():.2f} px, outside "
              f"{np.array(err_cut)[:, 1:].max():.1f} px; full homography: outside "
              f"{np.array(err_full)[:, 1:].max():.1f} px")
        assert inside.max() < 0.5
        assert np.array(err_cut)[:, 1:].max() < 1.0
        assert np.array(err_full)[:, 1:].max() > 2.0  # what the affine move avoids


def _grown(corner: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The 300x200 px outline of ``_frames(0)`` moved to have its top-left corner at
    ``corner``, and that outline grown 9 % about the corner (three ``MAX_LINEAR_STEP``)."""
    start, _ = _frames(0)
    start = start - start[0] + np.asarray(corner)
    return start, start[0] + (start - start[0]) * (1.0 + 3 * MAX_LINEAR_STEP)


def test_a_sliver_s_step_beyond_the_linear_limit_keeps_its_shape() -> None:
    """A sliver of the plate in view (45x55 px, under ``SLIVER_PIXELS``) grows 9 % between
    frames, more than ``MAX_LINEAR_STEP`` lets its affine step take: the outline only moves
    (its rotation and shift), its shape (and what is out of view) kept.  OpenCV's ECC writes
    its result into the warp it starts at, so a shift kept for this once came back as the
    affine step it was to replace."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    start, grown = _grown((595.0, 425.0))
    assert 45 * 55 < SLIVER_PIXELS
    gray = cv2.cvtColor(place(poster, grown, seed=1), cv2.COLOR_BGR2GRAY)
    hom = homography_to(ref, start)
    moved = align_cut(ref, gray, hom)
    assert moved is not None
    before, after = project_corners(ref, hom), project_corners(ref, moved)
    assert np.allclose(_sides(after), _sides(before), atol=1e-6)  # moved as a rigid body


def test_a_large_part_in_view_growing_is_followed() -> None:
    """A sixth of the plate in view (100x90 px, over ``SLIVER_PIXELS``) grows 9 % in a
    frame: that stretch is measured, not wandering, and the affine step takes it whole (the
    flown square's roll and its plates entering stretch 0.04-0.3 a frame on 10000-17000 px;
    held to a shift, they were lost)."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    start, grown = _grown((540.0, 390.0))
    gray = cv2.cvtColor(place(poster, grown, seed=1), cv2.COLOR_BGR2GRAY)
    moved = align_cut(ref, gray, homography_to(ref, start))
    assert moved is not None
    error = np.abs(project_corners(ref, moved) - grown).max()
    print(f"the grown outline's corners within {error:.2f} px")
    assert error < 2.0


def _sides(quad: np.ndarray) -> np.ndarray:
    """The six distances between a quad's corners (its shape, not where it is)."""
    return np.array([np.linalg.norm(quad[i] - quad[j]) for i in range(4) for j in range(i)])


def test_a_cut_plate_turning_with_the_camera_is_followed() -> None:
    """The image turns 3 deg a frame about the plate's corner in view (a camera rolling):
    a rotation is no stretch, so the affine step follows it whole, far corners too."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    start, _ = _frames(1)
    hom = homography_to(ref, start)
    truth = start
    for k in range(1, 5):
        a = np.radians(3.0 * k)
        turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        truth = (start - start[0]) @ turn.T + start[0]
        gray = cv2.cvtColor(place(poster, truth, seed=k), cv2.COLOR_BGR2GRAY)
        moved = align_cut(ref, gray, hom)
        assert moved is not None, k
        hom = moved
    assert np.abs(project_corners(ref, hom) - truth).max() < 2.0


def test_too_little_in_view_is_refused() -> None:
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    corners = np.array([[636.0, 476.0], [936.0, 476.0], [936.0, 676.0], [636.0, 676.0]])
    gray = cv2.cvtColor(place(poster, corners), cv2.COLOR_BGR2GRAY)
    assert align_cut(ref, gray, homography_to(ref, corners)) is None


def test_the_box_shift_follows_the_edges_inside_the_image() -> None:
    """A plate cut at the right: its box's left edge moves with it, its right edge (out of
    the image) says nothing; a plate cut on both sides of an axis gives no shift there."""
    assert box_shift((500.0, 100.0, 200.0, 80.0), (488.0, 103.0, 200.0, 80.0), 640, 480) \
        == (-12.0, 3.0)
    assert box_shift((-50.0, 100.0, 200.0, 80.0), (-40.0, 100.0, 200.0, 80.0), 640, 480) \
        == (10.0, 0.0)
    assert box_shift((-5.0, 0.0, 700.0, 80.0), (-9.0, 0.0, 700.0, 80.0), 640, 480)[0] == 0.0


def test_a_cut_plate_sliding_fast_is_held_from_its_box_shift() -> None:
    """18 px a frame: started where the plate was, the alignment lost it at the third frame
    (measured); started where its box moved (``shifted``), it holds the corner inside."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    start = np.array([[400.0, 330.0], [700.0, 336.0], [696.0, 536.0], [404.0, 530.0]])
    hom = homography_to(ref, start)
    for k in range(1, 6):
        truth = start - np.array([18.0 * k, 0.0])
        gray = cv2.cvtColor(place(poster, truth, seed=k), cv2.COLOR_BGR2GRAY)
        moved = align_cut(ref, gray, shifted(hom, -18.0, 0.0))
        assert moved is not None
        hom = moved
        assert np.abs(project_corners(ref, hom)[0] - truth[0]).max() < 0.5


def test_a_cut_plate_far_from_its_prediction_is_found_by_the_shift_search() -> None:
    """A plate a quarter in view, predicted 26 px left and 19 px up of where it is (an
    autopilot's dead-reckoned pose): the ECC alone does not reach it, the search over
    shifts gives a start from which it does, to within a pixel."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    truth = np.array([[470.0, 330.0], [770.0, 334.0], [766.0, 534.0], [474.0, 530.0]])
    gray = cv2.cvtColor(place(poster, truth, seed=2), cv2.COLOR_BGR2GRAY)
    predicted = shifted(homography_to(ref, truth), -26.0, -19.0)
    alone = align_cut(ref, gray, predicted)
    assert alone is None or np.abs(project_corners(ref, alone) - truth).max() > 5.0
    moved = search_shift(ref, gray, predicted, 30.0)
    assert moved is not None and np.abs(np.subtract(moved, (26.0, 19.0))).max() <= 1.0
    found = align_cut(ref, gray, shifted(predicted, *moved))
    assert found is not None
    assert np.abs(project_corners(ref, found) - truth).max() < 1.0


def test_the_shift_search_finds_nothing_where_the_plate_is_not() -> None:
    """Out of its radius (the plate 60 px from the prediction, radius 30) or absent (a
    flat plate where the poster was): no shift correlates well enough."""
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    truth = np.array([[470.0, 330.0], [770.0, 334.0], [766.0, 534.0], [474.0, 530.0]])
    gray = cv2.cvtColor(place(poster, truth, seed=2), cv2.COLOR_BGR2GRAY)
    far = shifted(homography_to(ref, truth), -60.0, 0.0)
    assert search_shift(ref, gray, far, 30.0) is None
    assert search_shift(ref, gray, far, 70.0) == (60.0, 0.0)  # found once within reach
    empty = cv2.cvtColor(place(poster * 0 + 128, truth, seed=2), cv2.COLOR_BGR2GRAY)
    assert search_shift(ref, empty, homography_to(ref, truth), 30.0) is None
