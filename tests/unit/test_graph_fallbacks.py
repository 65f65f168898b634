"""Nothing silent in the graph solver: damping added to a singular system, a covariance from
a damped factorisation and the general sparse path are reported (``info["fallbacks"]``, also
among the warnings and in summary.json)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.solver.layout import factorize
from vnav_graph.estimators.graph.solver.outputs import fallback_notes


def test_factorize_reports_the_damping_a_singular_system_needed():
    ab = np.array([[2.0, 2.0, 2.0], [-1.0, -1.0, 0.0]])  # [[2,-1,0],[-1,2,-1],[0,-1,2]]: SPD
    _, mu = factorize(ab, np.zeros((3, 0)), np.zeros((0, 0)))
    assert mu == 0.0
    singular = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])  # diag(1, 1, 0)
    fac, mu = factorize(singular, np.zeros((3, 0)), np.zeros((0, 0)))
    assert mu == 1e-9  # the first step of the damping ladder
    x = fac.solve(np.array([1.0, 2.0, 0.0]))
    np.testing.assert_allclose(x[:2], [1.0, 2.0], rtol=1e-6)


def test_fallback_notes_name_each_fallback():
    cfg = GraphConfig()
    clean = SimpleNamespace(singular_damping=0.0, solver="banded")
    assert fallback_notes(clean, cfg, 0.0) == []
    res = SimpleNamespace(singular_damping=1e-7, solver="general")
    notes = fallback_notes(res, cfg, 1e-9)
    assert len(notes) == 3
    assert notes[0].startswith("the Gauss-Newton system was numerically singular: Marquardt "
                               "damping up to 1e-07")
    assert "sigmas understate" in notes[1]
    assert notes[2].startswith("general sparse solver")
    # a general path the user asked for is a choice, not a fallback
    assert fallback_notes(res, GraphConfig(solver="general"), 0.0)[1:] == []
