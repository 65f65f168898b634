"""``isam2.linear_factors.container`` (one LAPACK Cholesky, a GaussianConditional of any number
of keys) against ``solver.general.information_factor`` (≤ 3-key Hessian pieces summed and
factored by GTSAM): the same LinearContainerFactor to round-off, for the baro and the
GNSS-error-state key layouts, and the same fallback for an indefinite block."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, C, G, K, X

from vnav_graph.estimators.graph.isam2.linear_factors import (
    BARO_BLOCKS,
    container,
    containers,
    gnss_gm_blocks,
)
from vnav_graph.estimators.graph.solver.general import information_factor

LAYOUTS = {
    "baro": (BARO_BLOCKS, [X(7), X(8), C(7), C(8), K(0), B(7)], (19, 22)),
    "gnss_gm": (gnss_gm_blocks(1), [X(7), X(8), B(7), G(7), G(8)], (15, 18)),
}


def _lin(keys: list[int], rng: np.random.Generator) -> gtsam.Values:
    lin = gtsam.Values()
    for key in keys:
        ch = chr(gtsam.Symbol(key).chr())
        if ch == "x":
            lin.insert(key, gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3)),
                                        rng.normal(size=3) * 100))
        elif ch == "b":
            lin.insert(key, gtsam.imuBias.ConstantBias(rng.normal(size=3), rng.normal(size=3)))
        else:
            lin.insert(key, rng.normal(size=2 if ch == "k" else 1))
    return lin


def _jacobian(f: gtsam.LinearContainerFactor, lin: gtsam.Values) -> np.ndarray:
    return np.asarray(f.linearize(lin).augmentedJacobian())


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("seed", range(5))
def test_equal_to_hessian_pieces(layout: str, seed: int) -> None:
    blocks, keys, zero = LAYOUTS[layout]
    rng = np.random.default_rng(seed)
    n = sum(w for _, w in blocks)
    # rows of very different scales (metres, radians, µ-level biases), B's gyro part zero
    jac = rng.normal(size=(3 * n, n)) * 10.0 ** rng.uniform(-2, 4, size=n)
    jac[:, zero[0]:zero[1]] = 0.0
    lam, eta = jac.T @ jac, rng.normal(size=n) * 100
    lin = _lin(keys, rng)
    old, new = information_factor(keys, lam, eta, blocks, lin), container(keys, lam, eta,
                                                                          blocks, lin)
    assert list(new.keys()) == list(old.keys())
    a_old, a_new = _jacobian(old, lin), _jacobian(new, lin)
    assert a_new.shape == a_old.shape
    assert np.max(np.abs(a_new - a_old)) <= 1e-12 * np.max(np.abs(a_old))
    # and the same quadratic at another point (the container's relinearised offset)
    other = _lin(keys, np.random.default_rng(seed + 100))
    assert np.allclose(_jacobian(new, other), _jacobian(old, other), rtol=0,
                       atol=1e-12 * np.max(np.abs(a_old)))


def test_indefinite_block_takes_the_pieces_path() -> None:
    """A block with a negative eigenvalue (rounding of a far linearisation point): LAPACK
    refuses it, and the factor is information_factor's, bitwise."""
    blocks, keys, _ = LAYOUTS["baro"]
    rng = np.random.default_rng(3)
    n = sum(w for _, w in blocks)
    q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    w = np.abs(rng.normal(size=n)) * 1e3
    w[4] = -0.05
    lam, eta = (q * w) @ q.T, rng.normal(size=n)
    lin = _lin(keys, rng)
    a_old = _jacobian(information_factor(keys, lam, eta, blocks, lin), lin)
    assert np.array_equal(_jacobian(container(keys, lam, eta, blocks, lin), lin), a_old)


def _baro_stack(rng: np.random.Generator, g: int) -> tuple[list[list[int]], np.ndarray,
                                                            np.ndarray]:
    n = sum(w for _, w in BARO_BLOCKS)
    keys_of = [[X(m), X(m + 1), C(m), C(m + 1), K(m // 3), B(m)] for m in range(4, 4 + g)]
    lam, eta = np.zeros((g, n, n)), rng.normal(size=(g, n)) * 100
    for i in range(g):
        jac = rng.normal(size=(3 * n, n)) * 10.0 ** rng.uniform(-2, 4, size=n)
        jac[:, 19:22] = 0.0
        lam[i] = jac.T @ jac
    return keys_of, lam, eta


def _stack_lin(keys_of: list[list[int]], rng: np.random.Generator) -> gtsam.Values:
    lin = gtsam.Values()
    for key in sorted({key for kk in keys_of for key in kk}):
        lin.insert(_lin([key], rng))
    return lin


def test_batched_equals_one_by_one() -> None:
    """``containers`` (one batched Cholesky) gives each block's ``information_factor``."""
    rng = np.random.default_rng(11)
    keys_of, lam, eta = _baro_stack(rng, 6)
    lin = _stack_lin(keys_of, rng)
    got = containers(keys_of, lam, eta, BARO_BLOCKS, lin)
    assert len(got) == 6
    for i, kk in enumerate(keys_of):
        a_old = _jacobian(information_factor(kk, lam[i], eta[i], BARO_BLOCKS, lin), lin)
        assert list(got[i].keys()) == sorted(kk)
        assert np.max(np.abs(_jacobian(got[i], lin) - a_old)) <= 1e-12 * np.max(np.abs(a_old))


def test_batched_with_an_indefinite_block() -> None:
    """One indefinite block in the stack: every block as ``container`` builds it alone."""
    rng = np.random.default_rng(12)
    keys_of, lam, eta = _baro_stack(rng, 4)
    w, v = np.linalg.eigh(lam[2])
    w[0] = -0.05
    lam[2] = (v * w) @ v.T
    lin = _stack_lin(keys_of, rng)
    got = containers(keys_of, lam, eta, BARO_BLOCKS, lin)
    for i, kk in enumerate(keys_of):
        assert np.array_equal(_jacobian(got[i], lin),
                              _jacobian(container(kk, lam[i], eta[i], BARO_BLOCKS, lin), lin))
