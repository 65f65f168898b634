"""Shared fixtures: deterministic RNGs, short simulated drives, the shared real-data folder."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path | None:
    """Real logs from $VNAV_DATA or ../shared/data next to the repository, if present."""
    env = os.environ.get("VNAV_DATA")
    for cand in ([Path(env)] if env else []) + [REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    return None


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def data_dir() -> Path:
    d = shared_data_dir()
    if d is None:
        pytest.skip("real logs not found: set VNAV_DATA or place them in ../shared/data")
    return d
