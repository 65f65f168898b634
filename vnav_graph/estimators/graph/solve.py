"""Batch solver of ``graph-batch``: banded-arrow normal equations of the linearised C++ graph
plus the interval terms, Gauss-Newton with Levenberg-Marquardt fallback, post-solve GNSS gate
(details and measurements in ``docs/graph.md``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, K, V, X

from ...types import (
    FloatArray,
)
from . import factors as gf
from . import linalg as gla
from .problem import (
    Problem,
    gnss_batch_idx,
    gnss_chi2,
    interval_rows,
    states_from_values,
)

# ----------------------------------------------------------------------------------------
# Batch Gauss-Newton on our own banded-arrow normal equations (``linalg``)


@dataclass
class Layout:
    """Column layout of the batch normal equations: keyframe k owns columns
    k·bs + [X (6, Pose3 tangent: rotation, translation), V (3), B (6, accel then gyro), C (1)]
    (bs = 16, or 15 without baro), then the global (s, τd) of K(0). ``g2m`` maps GTSAM's
    sparse-Jacobian columns (keys in sorted order) to ours."""

    nk: int
    bs: int
    has_baro: bool
    n_band: int
    n_cols: int
    g2m: np.ndarray
    keys: list[Any]
    pattern: Any = None  # SparsePattern of the graph last linearised with this layout

    @property
    def bandwidth(self) -> int:
        return 2 * self.bs - 1

    @property
    def term_cols(self) -> np.ndarray:
        """Interval-term columns (``factors`` order) present in this layout."""
        core = np.arange(gf.N_CORE if self.has_baro else 12)
        return np.r_[core, np.arange(gf.N_CORE, gf.N_COLS)]

    def block_cols(self, k: np.ndarray) -> np.ndarray:
        """Our columns of the interval-term blocks (X_k, X_k+1, [C_k, C_k+1, K,] accel bias
        of B_k), in the order of ``term_cols`` (G, 19|15)."""
        k = np.asarray(k)[:, None]
        six = np.arange(6)[None, :]
        parts = [k * self.bs + six, (k + 1) * self.bs + six]
        if self.has_baro:
            parts += [k * self.bs + 15, (k + 1) * self.bs + 15,
                      np.full_like(k, self.n_band), np.full_like(k, self.n_band + 1)]
        parts.append(k * self.bs + 9 + np.arange(3)[None, :])
        return np.concatenate(parts, axis=1)

    def vector_values(self, delta: FloatArray) -> Any:
        vv = gtsam.VectorValues()
        ins = vv.insert
        bs = self.bs
        d = delta[:self.n_band].reshape(self.nk, bs)
        for k in range(self.nk):
            row = d[k]
            ins(X(k), row[0:6])
            ins(V(k), row[6:9])
            ins(B(k), row[9:15])
            if self.has_baro:
                ins(C(k), row[15:16])
        if self.has_baro:
            ins(K(0), delta[self.n_band:])
        return vv


def layout(P: Problem) -> Layout:
    nk = P.n_kf
    has_baro = P.drive.baro is not None
    bs = 16 if has_baro else 15
    n_band = nk * bs
    items = []
    for k in range(nk):
        o = k * bs
        items += [(X(k), 6, o), (V(k), 3, o + 6), (B(k), 6, o + 9)]
        if has_baro:
            items.append((C(k), 1, o + 15))
    if has_baro:
        items.append((K(0), 2, n_band))
    items.sort(key=lambda it: it[0])
    g2m = np.concatenate([off + np.arange(dim) for _, dim, off in items])
    n_cols = n_band + (2 if has_baro else 0)
    return Layout(nk, bs, has_baro, n_band, n_cols, g2m, [it[0] for it in items])


@dataclass
class BatchResult:
    values: Any
    graph: Any  # C++ NonlinearFactorGraph
    cost: float
    iterations: int
    calib_of_kf: np.ndarray
    layout: Layout
    rows: gf.IntervalRows  # interval terms linearised at ``values``
    fac: gla.ArrowFactor | None = None  # factorised normal equations at ``values``, if kept
    bias_lag: float = 0.0  # baro-bias read time offset of the last solve (baro_rows)
    stop: str = "converged"  # "converged" | "max_iterations" | "no_descent"

    @property
    def converged(self) -> bool:
        return self.stop == "converged"


@dataclass
class SparsePattern:
    """Row/column bookkeeping of GTSAM's sparse Jacobian of one graph: the pattern (entry
    order included) is the same at every linearisation point, so it is computed once."""

    i: np.ndarray
    j: np.ndarray
    rhs_entries: np.ndarray  # entries of the right-hand-side column
    rhs_rows: np.ndarray
    a_sorted: np.ndarray  # matrix entries, ordered by row
    cols_sorted: np.ndarray  # their columns in our layout
    indptr: np.ndarray
    n_rows: int


def sparse_pattern(lay: Layout, i: np.ndarray, j: np.ndarray) -> SparsePattern:
    pat = lay.pattern
    if pat is not None and np.array_equal(pat.i, i) and np.array_equal(pat.j, j):
        return pat
    if int(j.max()) != lay.n_cols:
        raise RuntimeError("graph: linearised C++ graph does not cover the expected variables")
    is_b = j == lay.n_cols
    nrow = int(i.max()) + 1
    a = np.flatnonzero(~is_b)
    order = np.argsort(i[a], kind="stable")
    pat = SparsePattern(i, j, np.flatnonzero(is_b), i[is_b], a[order],
                         lay.g2m[j[a[order]]],
                         np.r_[0, np.cumsum(np.bincount(i[a], minlength=nrow))], nrow)
    lay.pattern = pat
    return pat


def normal_equations(P: Problem, lay: Layout, graph: Any, vals: Any,
                      rows: gf.IntervalRows) -> tuple[Any, ...]:
    """Arrow-form normal equations of the C++ factors (GTSAM linearisation, sparse Jacobian)
    plus the interval terms (per-interval information blocks)."""
    gfg = graph.linearize(vals)
    sj = gfg.sparseJacobian_()
    pat = sparse_pattern(lay, sj[0].astype(np.int64) - 1, sj[1].astype(np.int64) - 1)
    v = sj[2]
    b = np.zeros(pat.n_rows)
    b[pat.rhs_rows] = v[pat.rhs_entries]
    # interval terms: reduced per interval to (Λ_k, η_k) (batched BLAS), added as blocks
    groups, lam, eta, _ = gf.group_information(rows, P.n_kf - 1)
    tc = lay.term_cols
    return gla.assemble(lay.n_cols, lay.n_band, lay.bandwidth, pat.indptr, pat.cols_sorted,
                        v[pat.a_sorted], b,
                        lay.block_cols(groups), lam[:, tc[:, None], tc[None, :]], eta[:, tc])


def factorize(ab: FloatArray, bm: FloatArray, dm: FloatArray) -> gla.ArrowFactor:
    """Cholesky of the normal equations; if H is numerically singular (e.g. 1 Hz averaged
    IMU with an unobservable direction), retry with growing Marquardt damping μ·diag(H)."""
    mu = 0.0
    for _ in range(6):
        try:
            if mu == 0.0:
                return gla.factorize(ab, bm, dm)
            ab2 = ab.copy()
            ab2[0] += mu * ab[0] + 1e-12
            return gla.factorize(ab2, bm, dm + np.diag(mu * np.diag(dm) + 1e-12))
        except gla.LinAlgError:
            mu = 1e-9 if mu == 0.0 else mu * 100.0
    raise RuntimeError(
        "graph: the Gauss-Newton system stays singular even with Marquardt damping 1e-1·diag(H) "
        "— the drive does not determine the states (check IMU rate/units and GNSS coverage)")


def damped(ab: FloatArray, bm: FloatArray, dm: FloatArray, mu: float) -> gla.ArrowFactor:
    """Factorisation of H + μ·diag(H) (Levenberg-Marquardt damping)."""
    ab2 = ab.copy()
    ab2[0] *= 1.0 + mu
    return factorize(ab2, bm, dm + mu * np.diag(np.diag(dm)))


def gn_core(P: Problem, lay: Layout, graph: Any, vals: Any, calib_of_kf: np.ndarray,
             pri: dict[str, float]) -> BatchResult:
    """Gauss-Newton on the total cost (C++ factors + interval terms); a step that raises the
    cost is retried with Levenberg-Marquardt damping μ·diag(H) (μ from 1e-5, ×10 per
    retry, ÷10 after a success, back to plain Gauss-Newton below 1e-6). On the simulated
    drives every full step is accepted; on hovering-multirotor logs the weakly determined
    heading makes the full step overshoot (docs/graph.md). The interval rows evaluated at an
    accepted candidate are reused as its linearisation."""
    st = states_from_values(P, vals, calib_of_kf)
    # the baro bias is read at t_s − λ with λ fixed while τd moves, so that the cost is smooth
    # along τd (factors.baro_rows); λ follows τd when they drift > bias_lag_tol apart
    lag = float(np.median(st.latency))
    rows = interval_rows(P, st, pri, lag)
    cost = graph.error(vals) + 0.5 * float(rows.r @ rows.r)
    it = 0
    fac = None
    mu = 0.0
    converged = False
    failed = False
    for it in range(1, P.cfg.max_iterations + 1):
        converged = False
        ab, bm, dm, g = normal_equations(P, lay, graph, vals, rows)
        fac = factorize(ab, bm, dm)
        delta = fac.solve(g)
        dec = 0.5 * float(delta @ g)  # decrease predicted by the quadratic model
        if P.cfg.verbose:
            print(f"GN it {it}: predicted decrease {dec:.3g}")
        if dec < P.cfg.abs_tol:
            # converged at ``vals``: the step is not taken, and this factorisation — of the
            # normal equations at the solution — is kept for the covariance
            converged = True
            break
        fac = None
        if mu > 0.0:
            delta = damped(ab, bm, dm, mu).solve(g)
        failed = False
        while True:
            cand = vals.retract(lay.vector_values(delta))
            st_c = states_from_values(P, cand, calib_of_kf)
            lat = float(np.median(st_c.latency))
            lag_c = lat if abs(lat - lag) > P.cfg.bias_lag_tol else lag
            rows_c = interval_rows(P, st_c, pri, lag_c)
            new_cost = graph.error(cand) + 0.5 * float(rows_c.r @ rows_c.r)
            ref = cost
            if lag_c != lag and new_cost > cost:
                # λ moved with τd: a slightly different cost function — compare the
                # candidate with the current point under the new λ (rare: early iterations
                # gain far more than the ≈ 10 that moving λ by tens of ms changes)
                r_ref = interval_rows(P, st, pri, lag_c).r
                ref = graph.error(vals) + 0.5 * float(r_ref @ r_ref)
            if new_cost <= ref * (1 + 1e-12):
                mu = 0.0 if mu <= 1e-6 else mu / 10.0
                break
            if mu == 0.0 and abs(new_cost - ref) < P.cfg.rel_tol * ref:
                converged = True
                break  # converged: the change is at round-off level
            mu = 1e-5 if mu == 0.0 else mu * 10.0
            if mu > 1e3:
                failed = True  # no descent even as a tiny gradient step: stop here
                break
            delta = damped(ab, bm, dm, mu).solve(g)
        if failed:
            if P.cfg.verbose:
                print(f"GN it {it}: no step lowers the cost (μ > 1e3); stopping")
            break
        rel = (cost - new_cost) / max(cost, 1e-12)
        if P.cfg.verbose:
            print(f"GN it {it}: cost {cost:.10g} -> {new_cost:.10g} μ {mu:.0e}"
                  + (f" (bias lag {lag:.4f} -> {lag_c:.4f} s)" if lag_c != lag else ""))
        cost_prev = cost
        vals, st, rows, cost = cand, st_c, rows_c, new_cost
        if lag_c != lag:
            lag = lag_c  # a new cost function: no convergence test on this step
            continue
        if mu == 0.0 and (abs(rel) < P.cfg.rel_tol or abs(cost_prev - cost) < P.cfg.abs_tol):
            converged = True
            break
    stop = "converged" if converged else ("no_descent" if failed else "max_iterations")
    return BatchResult(vals, graph, cost, it, calib_of_kf, lay, rows, fac, lag, stop)


def gauss_newton(P: Problem, graph: Any, vals: Any, calib_of_kf: np.ndarray,
                  pri: dict[str, float]) -> BatchResult:
    """Gauss-Newton solve, then the post-solve GNSS gate: fixes whose whitened residual χ²
    (3 dof position, 6 with velocity) exceeds the ``gnss_gate_prob`` quantile are rejected
    and the problem re-solved from the current solution (≤ ``gate_rounds`` rounds).
    The residual of a fix that took part in the fit is smaller than its innovation, so the
    gate is conservative (Groves §17.3)."""
    lay = layout(P)
    res = gn_core(P, lay, graph, vals, calib_of_kf, pri)
    if P.cfg.gnss_gate_prob <= 0:
        return res
    from scipy.stats import chi2

    iters = res.iterations
    for _ in range(P.cfg.gate_rounds):
        idx = gnss_batch_idx(P)
        if idx.size == 0:
            break
        st = states_from_values(P, res.values, calib_of_kf)
        c2, dof = gnss_chi2(P, st, idx)
        # post-solve gate at the squared tail probability: a false rejection costs a whole
        # re-solve, a glitch has χ² in the thousands either way
        bad = c2 > chi2.ppf(1.0 - (1.0 - P.cfg.gnss_gate_prob) ** 2, dof)
        if not np.any(bad) or np.all(bad):
            break
        P.g_use[idx[bad]] = False
        P.g_rej_post += int(bad.sum())
        res = gn_core(P, lay, graph, res.values, calib_of_kf, pri)
        iters += res.iterations
    res.iterations = iters
    return res



