"""``information_factor`` on a block that rounding made indefinite (GTSAM's Cholesky refuses
it, with a message whose first line is empty): it is floored at the rounding level and
built."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, X

from vnav_graph.estimators.graph.solver.general import first_line, information_factor

BLOCKS = ((0, 6), (6, 6))


def _values() -> gtsam.Values:
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose3())
    v.insert(B(0), gtsam.imuBias.ConstantBias())
    return v


def _indefinite_by_rounding() -> np.ndarray:
    """Eigenvalues 1e15, 1e7, 1e2, eight zeros and −0.03: the spread of a baro block at a
    far linearisation point (−0.027 against 1.2e15 measured), where ε·1e15 ≈ 0.2."""
    q, _ = np.linalg.qr(np.random.default_rng(0).standard_normal((12, 12)))
    w = np.r_[-0.03, np.zeros(8), 1e2, 1e7, 1e15]
    return (q * w) @ q.T


def test_a_block_indefinite_by_rounding_is_built_at_its_information():
    lam = _indefinite_by_rounding()
    v = _values()
    f = information_factor([X(0), B(0)], lam, np.zeros(12), BLOCKS, v)
    jf = f.linearize(v)
    order = np.r_[[np.arange(6) + (0 if k == X(0) else 6) for k in jf.keys()]].ravel()
    h = jf.information()
    # the same information up to the block's rounding level (10·n·ε·max|λ| ≈ 27)
    assert np.max(np.abs(h - lam[np.ix_(order, order)])) < 100.0


@pytest.mark.parametrize(("msg", "line"), [
    ("\nIndeterminate linear system detected\nmore", "Indeterminate linear system detected"),
    ("", "RuntimeError with an empty message"),
])
def test_first_line_skips_empty_lines(msg, line):
    assert first_line(RuntimeError(msg)) == line
