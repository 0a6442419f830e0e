"""The illumination gain's pure functions (tracker/illumination.py)."""

from __future__ import annotations

import numpy as np

from tracker import illumination
from tracker.config import IlluminationConfig
from tracker.window import Window


def _window(value: int) -> Window:
    return Window(0, 0, 1.0, 1.0, np.full((8, 8, 3), value, np.uint8))


def test_compensation_multiplies_colour_windows_by_the_gain() -> None:
    light = IlluminationConfig()
    gain = illumination.Gain(np.full(3, 2.0), np.ones(3), np.ones(3))
    lit = illumination.compensate(_window(100), gain, light, "colour")
    assert np.all(lit.patch == 200)
    assert np.all(illumination.compensate(_window(200), gain, light, "colour").patch == 255)
    grey = _window(100)
    assert illumination.compensate(grey, gain, light, "grayscale") is grey  # colour only
    unity = illumination.Gain(np.ones(3), np.ones(3), np.ones(3))
    same = _window(100)
    assert illumination.compensate(same, unity, light, "colour") is same


def test_dead_band_leaves_small_drifts_alone() -> None:
    light = IlluminationConfig(gain_deadband=0.1)
    np.testing.assert_allclose(
        illumination.effective(np.array([1.05, 0.95, 1.5]), light), [1.0, 1.0, 1.4]
    )


def test_a_darker_frame_raises_the_gain_at_the_rate() -> None:
    light = IlluminationConfig(gain_rate=0.3)
    bright = np.full((64, 64, 3), 120, np.uint8)
    gain = illumination.start(np.full(3, 120.0), bright)
    darker = illumination.from_frame(gain, bright // 2, light)
    np.testing.assert_allclose(darker.gain, 0.7 + 0.3 * 2.0)
    np.testing.assert_allclose(
        illumination.proposed(gain, np.full(3, 30.0), light), 0.7 + 0.3 * 4.0
    )
    np.testing.assert_allclose(  # 12x darker: the ratio stops at 4
        illumination.proposed(gain, np.full(3, 10.0), light), 0.7 + 0.3 * 4.0
    )
