"""Batch solver of ``graph-batch``: Gauss-Newton with Levenberg-Marquardt fallback on the
linearised C++ graph plus the interval terms, post-solve GNSS gate (details and measurements
in ``docs/graph.md``). The linear algebra is the banded-arrow fast path (``layout``,
``linalg``) when the graph's structure fits it, else GTSAM's sparse elimination
(``general``); ``GraphConfig.solver`` forces either."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import interval_factors as gf
from ..model.problem import (
    Problem,
    interval_rows,
    post_solve_rejections,
    states_from_values,
)
from .general import GeneralSystem
from .layout import (
    MAX_GLOBAL_DIM,
    BandedSystem,
    IntervalInfo,
    Layout,
    interval_info,
    linearize,
    make_layout,
)

# ----------------------------------------------------------------------------------------
# Batch Gauss-Newton over the linearised graph: banded-arrow fast path (``layout``) or GTSAM
# elimination (``general``), chosen from the structure of the graph


# a stalled full step (gain < abs_tol) counts as convergence only when the quadratic model
# at the point before it predicted less than this [½χ²] (a 1σ move along the step): a stalled
# step where the model predicts more is a model that misses the curvature, not an optimum
# (docs/graph.md, "Stopping and damping")
STALL_MAX_PREDICTED = 1.0
# Levenberg-Marquardt damping μ·diag(H): from 1e-5 on the first refused step, × LM_FACTOR per
# refused step, ÷ LM_FACTOR per accepted one, plain Gauss-Newton again below LM_PLAIN_BELOW.
# With ×10 / ÷10 and plain below 1e-6 every third step in a curved valley is a full step that
# fails, and the solve creeps (docs/graph.md, "Stopping and damping")
LM_FACTOR = 5.0
LM_PLAIN_BELOW = 1e-9


@dataclass
class BatchResult:
    values: Any
    graph: Any  # C++ NonlinearFactorGraph
    cost: float
    iterations: int
    calib_of_kf: np.ndarray
    layout: Layout
    rows: gf.IntervalRows  # interval terms linearised at ``values``
    system: Any = None  # linear system at ``values`` (BandedSystem | GeneralSystem), if kept
    bias_lag: float = 0.0  # baro-bias read time offset of the last solve (baro_rows)
    stop: str = "converged"  # "converged" | "max_iterations" | "no_descent"
    # ½χ² decrease the quadratic model predicted at the last linearisation (at the returned
    # point when converged; else at the point before the last step): what a solve stopped at
    # its cap or without descent still expected to gain
    predicted_decrease: float = 0.0
    # largest Marquardt damping a numerically singular system needed (0: none)
    singular_damping: float = 0.0

    @property
    def converged(self) -> bool:
        return self.stop == "converged"

    @property
    def solver(self) -> str:
        return "banded" if self.layout.banded else "general"


def batch_layout(P: Problem, graph: Any, vals: Any) -> Layout:
    """Column layout from the keys of the graph (``layout.make_layout``)."""
    return make_layout(P.n_kf, P.drive.baro is not None, graph.keyVector(), vals.dims(),
                       gm_dim=0 if P.gm is None else P.gm.dim)


def linear_system(P: Problem, lay: Layout, graph: Any, vals: Any,
                  info: IntervalInfo) -> BandedSystem | GeneralSystem:
    """The Gauss-Newton system at ``vals``: the C++ factors linearised by GTSAM plus the
    interval terms' information blocks (``layout.interval_info`` of their rows, formed by
    the caller so that it can drop the rows' Jacobian first). The first call decides the
    path (``GraphConfig.solver``; "auto": banded when the structure fits,
    ``Layout.fits_band``)."""
    if lay.banded is None:
        solver = P.cfg.solver
        gfg, pat, v = linearize(lay, graph, vals)
        fits = lay.fits_band()
        if solver == "banded" and not fits:
            raise ValueError(
                "graph: solver = 'banded' but the graph does not fit the keyframe band (a "
                "factor links keyframes more than one apart, or the added variables have more "
                f"than {MAX_GLOBAL_DIM} dimensions); use solver = 'auto' or 'general'")
        lay.banded = fits if solver == "auto" else solver == "banded"
        if lay.banded:
            return BandedSystem.build(lay, pat, v, info)
        lay.pattern = None  # the general path does not reuse it (``sparse_pattern``)
        del pat, v
        return GeneralSystem(lay, gfg, info)
    if lay.banded:
        _, pat, v = linearize(lay, graph, vals)
        return BandedSystem.build(lay, pat, v, info)
    return GeneralSystem(lay, graph.linearize(vals), info)


def gn_core(P: Problem, lay: Layout, graph: Any, vals: Any, calib_of_kf: np.ndarray,
             pri: dict[str, float]) -> BatchResult:
    """Gauss-Newton on the total cost (C++ factors + interval terms); a step that raises the
    cost is retried with Levenberg-Marquardt damping μ·diag(H) (μ from 1e-5, × ``LM_FACTOR``
    per retry, ÷ ``LM_FACTOR`` after a success, back to plain Gauss-Newton below
    ``LM_PLAIN_BELOW``). On the shipped scenarios every full step is accepted; where the
    heading is weakly determined (hovering multirotors, a phone inside GNSS-free windows, a
    drive without horizontal motion) the full step overshoots (docs/graph.md). The interval
    rows evaluated at an accepted candidate are reused as its linearisation."""
    st = states_from_values(P, vals, calib_of_kf)
    # the baro bias is read at t_s − λ with λ fixed while τd moves, so that the cost is smooth
    # along τd (factors.baro_rows); λ follows τd when they drift > bias_lag_tol apart
    lag = float(np.median(st.latency))
    rows = interval_rows(P, st, pri, lag)
    cost = graph.error(vals) + rows.cost
    it = 0
    dec = 0.0
    system = None
    mu = 0.0
    converged = False
    failed = False
    singular = 0.0
    for it in range(1, P.cfg.max_iterations + 1):
        converged = False
        # the system holds the rows' information: their Jacobian is not needed again (the
        # result keeps either this system or a candidate's full rows). It is dropped once
        # the information blocks are formed, before the C++ rows are linearised and the
        # system assembled (44 MB on a 1-hour drive; with it this was the solve's peak), and
        # so one set of rows, not two, is alive while the candidate's are evaluated
        info = interval_info(lay, rows)
        rows = rows.without_jac()
        system = linear_system(P, lay, graph, vals, info)
        del info
        delta, dec = system.step()  # dec: decrease predicted by the quadratic model
        singular = max(singular, system.damping)
        if P.cfg.verbose:
            print(f"GN it {it}: predicted decrease {dec:.3g}")
        if dec < P.cfg.abs_tol:
            # converged at ``vals``: the step is not taken, and this factorisation — of the
            # normal equations at the solution — is kept for the covariance
            converged = True
            break
        # the factorisation is not needed while candidates are evaluated (a damped step
        # factorises its own matrix; a solve that ends below refactorises for the
        # covariance): freed, it is not alive under the candidate's rows (the solve's peak)
        system.release_factor()
        if mu > 0.0:
            delta = system.damped(mu)
        failed = False
        while True:
            cand = vals.retract(delta)
            st_c = states_from_values(P, cand, calib_of_kf)
            lat = float(np.median(st_c.latency))
            lag_c = lat if abs(lat - lag) > P.cfg.bias_lag_tol else lag
            rows_c = interval_rows(P, st_c, pri, lag_c)
            new_cost = graph.error(cand) + rows_c.cost
            ref = cost
            if lag_c != lag and new_cost > cost:
                # λ moved with τd: a slightly different cost function — compare the
                # candidate with the current point under the new λ (rare: early iterations
                # gain far more than the ≈ 10 that moving λ by tens of ms changes)
                ref = graph.error(vals) + interval_rows(P, st, pri, lag_c).cost
            if new_cost <= ref * (1 + 1e-12):
                mu = 0.0 if mu <= LM_PLAIN_BELOW else mu / LM_FACTOR
                break
            if mu == 0.0 and abs(new_cost - ref) < P.cfg.rel_tol * ref:
                converged = True
                break  # converged: the change is at round-off level
            mu = 1e-5 if mu == 0.0 else mu * LM_FACTOR
            if mu > 1e3:
                failed = True  # no descent even as a tiny gradient step: stop here
                break
            delta = system.damped(mu)
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
        system = None
        del rows_c  # ``rows`` is the only reference: its Jacobian goes with without_jac()
        if lag_c != lag:
            lag = lag_c  # a new cost function: no convergence test on this step
            continue
        # a full step that gains less than abs_tol ends the solve only when the model at the
        # point before it predicted little more (``STALL_MAX_PREDICTED``); a larger prediction
        # is the model overshooting in a curved valley, where Gauss-Newton creeps on
        if mu == 0.0 and (abs(rel) < P.cfg.rel_tol or (abs(cost_prev - cost) < P.cfg.abs_tol
                                                        and dec < STALL_MAX_PREDICTED)):
            converged = True
            break
    stop = "converged" if converged else ("no_descent" if failed else "max_iterations")
    return BatchResult(vals, graph, cost, it, calib_of_kf, lay, rows, system, lag, stop,
                       float(dec), singular)


def evaluate_at(P: Problem, graph: Any, vals: Any, calib_of_kf: np.ndarray,
                pri: dict[str, float]) -> BatchResult:
    """The batch problem at ``vals`` without a step: its cost and rows there (what
    ``solver.outputs`` needs for the trajectory and the covariances at someone else's
    estimate, e.g. iSAM2's own)."""
    st = states_from_values(P, vals, calib_of_kf)
    lag = float(np.median(st.latency))
    rows = interval_rows(P, st, pri, lag)
    cost = graph.error(vals) + rows.cost
    return BatchResult(vals, graph, cost, 0, calib_of_kf, batch_layout(P, graph, vals), rows,
                       None, lag, "converged")


def gauss_newton(P: Problem, graph: Any, vals: Any, calib_of_kf: np.ndarray,
                  pri: dict[str, float]) -> BatchResult:
    """Gauss-Newton solve, then the post-solve GNSS gate: fixes whose whitened residual χ²
    (3 dof position, 6 with velocity) exceeds the ``gnss_gate_prob`` quantile are rejected
    and the problem re-solved from the current solution (≤ ``gate_rounds`` rounds).
    The residual of a fix that took part in the fit is smaller than its innovation, so the
    gate is conservative (Groves §17.3)."""
    lay = batch_layout(P, graph, vals)
    res = gn_core(P, lay, graph, vals, calib_of_kf, pri)
    if P.cfg.gnss_gate_prob <= 0:
        return res
    iters, singular = res.iterations, res.singular_damping
    for _ in range(P.cfg.gate_rounds):
        if not post_solve_rejections(P, states_from_values(P, res.values, calib_of_kf)).size:
            break
        res = gn_core(P, lay, graph, res.values, calib_of_kf, pri)
        iters += res.iterations
        singular = max(singular, res.singular_damping)
    res.iterations, res.singular_damping = iters, singular
    return res



