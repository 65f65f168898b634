"""``gnss_gm_auto`` (``estimators.gnss_auto``): the Gauss-Markov GNSS error state carried only
when the fixes' residuals of a first pass without it are correlated in time.

A white-error drive (hill-drive) keeps the first pass bit for bit; a correlated one (urban)
gives exactly the run with the state configured, and says so (info, warning, summary block).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.estimators import gnss_auto
from vnav_graph.estimators.ekf.filter import EKF, EKFRTS, EkfConfig
from vnav_graph.estimators.graph import GraphBatch, GraphConfig
from vnav_graph.evaluation.metrics import evaluate
from vnav_graph.sensors.gnss_model import GM_AUTO_SIGMAS, GM_AUTO_THRESHOLD
from vnav_graph.simulation.scenario import simulate

GM = {"gnss_gm_sd_h": 2.5, "gnss_gm_sd_v": 4.0, "gnss_gm_tau_s": 30.0}


def test_auto_needs_the_state_sigma():
    with pytest.raises(ValueError, match="gnss_gm_auto"):
        EkfConfig(gnss_gm_auto=True)
    with pytest.raises(ValueError, match="gnss_gm_auto"):
        GraphConfig(gnss_gm_auto=True)


@pytest.mark.parametrize(("ac", "on", "thr"), [
    ({"horiz": 0.10, "vert": 0.16, "pairs": 2500}, True, 0.15),  # either axis
    ({"horiz": 0.16, "vert": None, "pairs": 2500}, True, 0.15),
    ({"horiz": 0.15, "vert": -0.5, "pairs": 2500}, False, 0.15),  # strictly above
    # few pairs: 4σ of a white series' ρ̂ (σ = 1/√pairs) is the larger threshold
    ({"horiz": 0.20, "vert": 0.19, "pairs": 400}, False, 0.2),
    ({"horiz": 0.21, "vert": 0.0, "pairs": 400}, True, 0.2),
    ({"horiz": None, "vert": None, "pairs": 0}, False, np.inf),
    (None, False, np.inf),  # no GNSS
])
def test_decision_rule(monkeypatch, ac, on, thr):
    assert GM_AUTO_THRESHOLD == 0.15 and GM_AUTO_SIGMAS == 4.0
    monkeypatch.setattr(gnss_auto, "gnss_residual_autocorr", lambda est, drive: ac)
    dec = gnss_auto.gm_decision(None, None)
    assert dec["on"] is on and dec["threshold"] == pytest.approx(thr)


def test_white_errors_keep_the_first_pass():
    d = simulate("hill-drive", 1, duration_s=120.0)
    cfg = EkfConfig(fb_separation=False)
    auto = EKFRTS(replace(cfg, gnss_gm_auto=True, **GM)).run(d)
    plain = EKFRTS(cfg).run(d)
    dec = auto.info["gnss_gm_auto"]
    assert not dec["on"] and abs(dec["autocorr_h"]) < GM_AUTO_THRESHOLD
    np.testing.assert_array_equal(auto.trajectory.lla, plain.trajectory.lla)
    assert "gnss_gm" not in auto.info


@pytest.mark.parametrize("family", ["ekf", "graph-batch"])
def test_correlated_errors_turn_the_state_on(family):
    d = simulate("urban", 0, duration_s=200.0)
    if family == "ekf":
        auto = EKF(EkfConfig(gnss_gm_auto=True, **GM)).run(d)
        on = EKF(EkfConfig(**GM)).run(d)
    else:
        auto = GraphBatch(GraphConfig(gnss_gm_auto=True, **GM)).run(d)
        on = GraphBatch(GraphConfig(**GM)).run(d)
    dec = auto.info["gnss_gm_auto"]
    assert dec["on"] and max(dec["autocorr_h"], dec["autocorr_v"]) > GM_AUTO_THRESHOLD
    np.testing.assert_array_equal(auto.trajectory.lla, on.trajectory.lla)
    assert auto.info["gnss_gm"]["sd_h_m"] == 2.5
    assert any("correlated in time" in w for w in auto.info["warnings"])
    row = evaluate(auto, d)
    assert row["gnss_gm_auto"]["on"] and any("correlated in time" in w for w in row["warnings"])
