"""graph-batch's config gets 5 s keyframes on averaged low-rate (≤ 2 Hz) IMU logs (graph-isam2's
low-rate settings run on the 1 Hz car log in tests/integration/test_graph_real_logs.py)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from vnav_graph.estimators.graph.settings import (
    LOW_RATE_KEYFRAME_DT,
    GraphConfig,
    low_rate_config,
)


def _drive(rate_hz: float) -> SimpleNamespace:
    return SimpleNamespace(imu=SimpleNamespace(t=np.arange(0.0, 600.0, 1.0 / rate_hz)))


def test_low_rate_imu_gets_long_keyframes() -> None:
    """The documented rule (GraphConfig.keyframe_dt, docs/graph.md): 5 s keyframes on IMU logs
    averaged to 2 Hz or less, the 1 s default above that."""
    cfg = GraphConfig()
    assert cfg.keyframe_dt == 1.0 and LOW_RATE_KEYFRAME_DT == 5.0
    for rate_hz, keyframe_dt in ((1.0, 5.0), (2.0, 5.0), (2.5, 1.0), (100.0, 1.0)):
        assert low_rate_config(cfg, _drive(rate_hz)).keyframe_dt == keyframe_dt, rate_hz
    assert low_rate_config(cfg, _drive(100.0)) is cfg
    # a user's own keyframe spacing is kept
    own = replace(cfg, keyframe_dt=2.0)
    assert low_rate_config(own, _drive(1.0)) is own
