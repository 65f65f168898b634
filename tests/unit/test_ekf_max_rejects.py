"""The EKF's forced acceptance after refused fixes: a count, or a span of GNSS time."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vnav_graph.estimators.ekf.filter import max_rejects
from vnav_graph.estimators.ekf.settings import EkfConfig


def _drive(rate_hz: float) -> SimpleNamespace:
    return SimpleNamespace(gnss=SimpleNamespace(t=np.arange(0.0, 60.0, 1.0 / rate_hz)))


def test_count_by_default_and_span_over_the_fix_interval() -> None:
    assert max_rejects(EkfConfig(), _drive(10.0)) == 50
    span = EkfConfig(max_rejected_s=30.0)
    assert max_rejects(span, _drive(10.0)) == 300
    assert max_rejects(span, _drive(1.0)) == 30
    assert max_rejects(EkfConfig(max_rejected_s=0.01), _drive(1.0)) == 1
    assert max_rejects(span, SimpleNamespace(gnss=None)) == 50
