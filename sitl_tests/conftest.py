"""Shared fixtures of the SITL scenarios (sitl_tests/harness.py has the harness)."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.settings import Settings
from sitl_tests.harness import sitl_settings


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Default configuration, flight log in the test's temporary folder, monitoring off."""
    return sitl_settings(tmp_path)
