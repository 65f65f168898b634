"""A baro whose latency is far outside the estimators' prior is reported by every estimator
with a baro calibration (``estimators.checks.prior_conflict_notes``), and a baro inside it is not.

A scenario that fixes the latency gives the estimators the documented default prior
N(0.1 s, 0.1 s), never the truth (``sensors.model.baro_prior``). With a true latency of 1.0 s
on a 300 s hill-drive the data pull the estimate to ≈ 0.7 s, 6 prior σ out, while its own σ
(≈ 0.065 s) leaves the truth ≈ 4.5σ away: the case the note exists for. With 0.15 s the
estimates sit within 2 prior σ and nothing is noted."""

from __future__ import annotations

from dataclasses import replace

import pytest

from vnav_graph.estimators.checks import PRIOR_CONFLICT_Z
from vnav_graph.run.pipeline import run_estimators
from vnav_graph.simulation.scenario import load_scenario, simulate

ESTIMATORS = ["ekf-rts", "graph-batch", "vekf7"]


def _run(latency_s: float) -> dict:
    cfg = load_scenario("hill-drive", duration_s=300.0)
    cfg = replace(cfg, baro=replace(cfg.baro, latency_s=latency_s, latency_range_s=None))
    drive = simulate(cfg, 2)
    out = {r.name: r.estimate for r in run_estimators(drive, ESTIMATORS, False, None)}
    assert all(e is not None for e in out.values())
    return out


def test_a_latency_far_outside_the_prior_is_noted_by_every_family():
    for name, est in _run(1.0).items():
        lat = est.baro.latency_s
        assert lat.prior_mean == pytest.approx(0.1) and lat.prior_sd == pytest.approx(0.1)
        assert (lat.est - lat.prior_mean) / lat.prior_sd > PRIOR_CONFLICT_Z, name
        notes = est.info["baro_prior_conflict"]
        assert len(notes) == 1 and notes[0].startswith("baro latency +0.7"), (name, notes)
        assert notes[0] in est.info["warnings"]


def test_a_latency_inside_the_prior_is_not_noted():
    for name, est in _run(0.15).items():
        assert "baro_prior_conflict" not in est.info, name
        warns = est.info.get("warnings") or []
        assert not [w for w in warns if "prior σ from its prior" in w], name
