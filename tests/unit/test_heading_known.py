"""Heading scored where the estimator claims to know it: ``heading_known`` on arrays with a
known answer."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.metrics import HEADING_KNOWN_SD_DEG, heading_known


def test_scores_only_epochs_with_small_sigma_and_finds_when_it_stays_known():
    t = np.arange(0.0, 10.0, 0.5)  # 20 epochs
    err = np.where(t < 3.0, 90.0, 2.0)  # 90° off while σ says it does not know
    sd = np.where(t < 3.0, 100.0, 1.0)
    sd[10] = 6.0  # one excursion above the limit at t = 5 s
    rms, after = heading_known(t, err, sd)
    assert rms == pytest.approx(2.0)
    assert after == pytest.approx(5.5)  # stays known from the epoch after the excursion
    assert HEADING_KNOWN_SD_DEG == 5.0


def test_none_when_never_known_or_unknown_at_the_end_or_no_sigma():
    t = np.arange(5.0)
    assert heading_known(t, np.ones(5), np.full(5, 30.0)) == (None, None)
    rms, after = heading_known(t, np.ones(5), np.array([1.0, 1.0, 1.0, 1.0, 9.0]))
    assert rms == pytest.approx(1.0) and after is None
    assert heading_known(t, np.ones(5), None) == (None, None)
    assert heading_known(t, None, np.ones(5)) == (None, None)
    assert heading_known(t, np.ones(5), np.ones(5)) == (pytest.approx(1.0), 0.0)
