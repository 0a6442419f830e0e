"""Shared fixtures: small deterministic synthetic scenes (no shared data needed)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from companion.evaluation.synthetic import SynthSpec, generate


@pytest.fixture(scope="session")
def moving_sign() -> tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]:
    """60 frames of a sign moving over clutter, constant light."""
    return generate(SynthSpec(frames=60, width_px=320, height_px=240, illumination=False))


@pytest.fixture(scope="session")
def hidden_sign() -> tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]:
    """A sign that disappears for frames 20..34 and comes back."""
    spec = SynthSpec(
        frames=60, width_px=320, height_px=240, illumination=False, hidden_frames=(20, 35)
    )
    return generate(spec)
