"""The baro calibration's prior-conflict notes (``estimators.checks.prior_conflict_notes``): an
estimate more than ``PRIOR_CONFLICT_Z`` prior σ from its prior mean is reported, with its
numbers, in ``info["baro_prior_conflict"]`` and among the warnings."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.checks import (
    PRIOR_CONFLICT_Z,
    prior_conflict_notes,
    with_prior_conflict_notes,
)
from vnav_graph.types import BaroEstimate, Estimate, ParamEstimate, Trajectory


def _baro(lat: float, scale: float = 0.0, lat_mean: float | None = 0.1) -> BaroEstimate:
    return BaroEstimate(scale=ParamEstimate(scale, 0.005, 0.02, 0.0),
                        latency_s=ParamEstimate(lat, 0.05, 0.1, lat_mean),
                        bias_m=ParamEstimate(1.0, 0.3, 2.0))


def _estimate(baro: BaroEstimate, warnings: list[str] | None = None) -> Estimate:
    t = np.array([0.0, 1.0])
    traj = Trajectory(t, np.zeros((2, 3)), np.zeros((2, 3)))
    return Estimate("x", traj, frozenset({"alt"}), baro=baro,
                    info={"warnings": list(warnings or [])})


def test_a_latency_beyond_the_limit_is_noted_with_its_numbers():
    z = PRIOR_CONFLICT_Z + 0.5
    notes = prior_conflict_notes(_baro(0.1 - z * 0.1))
    assert len(notes) == 1
    assert notes[0].startswith("baro latency -0.45 ± 0.05 s is 5.5 prior σ from its prior "
                               "0.10 ± 0.10 s")


def test_inside_the_limit_or_without_a_prior_mean_nothing_is_noted():
    assert prior_conflict_notes(_baro(0.1 + (PRIOR_CONFLICT_Z - 0.5) * 0.1)) == []
    assert prior_conflict_notes(_baro(-2.0, lat_mean=None)) == []
    assert prior_conflict_notes(None) == []


def test_a_scale_beyond_the_limit_is_noted_in_percent():
    notes = prior_conflict_notes(_baro(0.1, scale=0.12))
    assert len(notes) == 1 and notes[0].startswith("baro scale +12.00 ± 0.50 % is 6.0 prior σ")


def test_the_notes_join_the_warnings_once():
    est = _estimate(_baro(-1.0), ["a solver warning"])
    once = with_prior_conflict_notes(est)
    assert once.info["baro_prior_conflict"] == prior_conflict_notes(est.baro)
    assert once.info["warnings"] == ["a solver warning", *once.info["baro_prior_conflict"]]
    # a nested re-run of an estimator already carries them: not added twice
    assert with_prior_conflict_notes(once).info["warnings"] == once.info["warnings"]
    plain = _estimate(_baro(0.12))
    assert with_prior_conflict_notes(plain) is plain


@pytest.mark.parametrize("z", [-7.0, 7.0])
def test_the_sign_does_not_matter(z: float):
    assert len(prior_conflict_notes(_baro(0.1 + z * 0.1))) == 1
