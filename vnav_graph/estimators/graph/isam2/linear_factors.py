"""Custom terms of ``graph-isam2``'s online pass: the baro samples and GNSS fixes between
keyframes as ``LinearContainerFactor``s, linearised once (numpy, ``factors``) at the current
estimate as soon as they have arrived, with the accelerometer-bias columns on B(k) and,
when carried, the GNSS error state G(k) (``docs/graph.md``). No Python callback runs inside
iSAM2."""

from __future__ import annotations

import dataclasses
from functools import cache
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, G, K, X
from scipy.linalg import lapack

from ..model import interval_factors as gf
from ..model.problem import Problem, nav_accel
from ..model.robust import reweight
from ..solver.general import information_factor, pad_information

# key blocks (first column, width) of the factors, in their padded columns (B's gyro part
# zero): baro — X(m), X(m+1), C(m), C(m+1), K(j), B(m) over the 19 ``factors`` columns + 3;
# GNSS with the error state of dimension d — X(k), X(k+1), B(k), G(k), G(k+1)
BARO_BLOCKS = (*gf.BLOCKS, (16, 6))


def gnss_gm_blocks(d: int) -> tuple[tuple[int, int], ...]:
    """Key blocks (first column, width) of a GNSS factor with G(k), G(k+1) of dimension d."""
    return ((0, 6), (6, 6), (12, 6), (18, d), (18 + d, d))


# GTSAM's Cholesky (``choleskyCareful``) takes a pivot at or below 1e-6 (after the square
# root) as a zero row; such blocks go the way of ``information_factor`` (margin ×10)
SMALL_PIVOT = 1e-5


@cache
def _sorted_columns(blocks: tuple[tuple[int, int], ...], order: tuple[int, ...]
                    ) -> tuple[np.ndarray, np.ndarray, tuple[tuple[int, int], ...]]:
    """The columns of ``blocks`` in the key order ``order``: their indices, the flat indices
    of the permuted Λ, and each key's (first column, width) in it."""
    cols = np.concatenate([np.arange(blocks[i][0], blocks[i][0] + blocks[i][1])
                           for i in order])
    n = int(max(a + w for a, w in blocks))
    at = np.cumsum([0] + [blocks[i][1] for i in order])
    return cols, (cols[:, None] * n + cols[None, :]).ravel(), tuple(
        (int(at[p]), blocks[i][1]) for p, i in enumerate(order))


def container(keys: list[int], lam: Any, eta: Any, blocks: tuple[tuple[int, int], ...],
              lin: Any) -> Any:
    """``general.information_factor`` (the information (Λ, η) over ``keys`` as a
    LinearContainerFactor at ``lin``) from one LAPACK Cholesky: the JacobianFactor
    [R | R⁻ᵀη] with Λ + 1e-9·I = RᵀR, its columns in ascending key order, as GTSAM's
    ``JacobianFactor(HessianFactor)`` of the summed ≤ 3-key pieces gives it (equal to
    round-off: 1e-16 relative), in 65–80 µs instead of 125–180 µs per factor (a factor with
    more than three keys is built as a ``GaussianConditional``, whose constructor takes a list
    of (key, block) terms of any length, then copied as a plain JacobianFactor). A block that
    LAPACK refuses or with a pivot GTSAM would take as zero goes through
    ``information_factor``."""
    order = tuple(sorted(range(len(keys)), key=keys.__getitem__))
    cols, flat, at = _sorted_columns(blocks, order)
    n = cols.size
    a = lam.take(flat).reshape(n, n)
    a.flat[::n + 1] += 1e-9  # as information_factor
    r, info = lapack.dpotrf(a, lower=0, clean=1, overwrite_a=1)
    if info != 0 or not r.diagonal().min() > SMALL_PIVOT:
        return information_factor(keys, lam, eta, blocks, lin)
    d = lapack.dtrtrs(r, eta.take(cols), lower=0, trans=1)[0]
    return _jacobian_container(keys, order, at, r, d, lin)


def containers(keys_of: list[list[int]], lam: Any, eta: Any,
               blocks: tuple[tuple[int, int], ...], lin: Any) -> list[Any]:
    """``container`` of a stack of blocks (Λ (G, n, n), η (G, n); ``keys_of[i]``: block i's
    keys, all in the same relative order) with one batched Cholesky. When the batch is
    refused (a block not positive definite), each block goes through ``container``."""
    order = tuple(sorted(range(len(keys_of[0])), key=keys_of[0].__getitem__))
    if any(tuple(sorted(range(len(kk)), key=kk.__getitem__)) != order for kk in keys_of):
        return [container(kk, lam[i], eta[i], blocks, lin) for i, kk in enumerate(keys_of)]
    cols, flat, at = _sorted_columns(blocks, order)
    g, n = lam.shape[0], cols.size
    a = lam.reshape(g, -1)[:, flat].reshape(g, n, n)
    a[:, np.arange(n), np.arange(n)] += 1e-9  # as information_factor
    try:
        r = np.swapaxes(np.linalg.cholesky(a), 1, 2)  # upper: Λ + 1e-9·I = RᵀR
    except np.linalg.LinAlgError:
        return [container(kk, lam[i], eta[i], blocks, lin) for i, kk in enumerate(keys_of)]
    ok = np.diagonal(r, axis1=1, axis2=2).min(axis=1) > SMALL_PIVOT
    e = eta[:, cols]
    out = []
    for i, kk in enumerate(keys_of):
        if not ok[i]:
            out.append(information_factor(kk, lam[i], eta[i], blocks, lin))
            continue
        d = lapack.dtrtrs(r[i], e[i], lower=0, trans=1)[0]
        out.append(_jacobian_container(kk, order, at, r[i], d, lin))
    return out


def _jacobian_container(keys: list[int], order: tuple[int, ...],
                        at: tuple[tuple[int, int], ...], r: Any, d: Any, lin: Any) -> Any:
    """The LinearContainerFactor of the JacobianFactor [R | d] over ``keys`` (columns in the
    key order ``order``, key p's at ``at[p]``), linearised at ``lin``."""
    terms = [(keys[i], r[:, c:c + w]) for i, (c, w) in zip(order, at, strict=True)]
    return gtsam.LinearContainerFactor(
        gtsam.JacobianFactor(gtsam.GaussianConditional(terms, len(keys), d, None)), lin)


def keyframe_states(P: Problem, k: int | list[int], rot: Any, pos: Any, vel: Any, bias: Any,
                    cb: Any, gg: Any, dg: Any = None) -> gf.KeyframeStates:
    """Keyframe states of the running arrays (views, not copies) for the rows of interval k
    (or of each interval in a list): the nav-frame acceleration of intervals k − 3 … k + 1
    at the current estimate, the GNSS height error ``gg`` when carried; (s, τd) zero
    (``baro_terms`` sets them). ``dg``: the gravity anomaly of every keyframe (K, 3), if
    known (it changes by ~3e-6 m/s² per metre: computed once per keyframe it saves the
    geodetic conversion at every rebuild), else computed here."""
    nk = P.n_kf
    st = gf.KeyframeStates(
        rot, pos, vel, bias[:, 0:3], cb, np.zeros(nk), np.zeros(nk),
        np.tile(np.array([0.0, 0.0, P.g0]), (nk, 1)), gg if P.gm is not None else None)
    if isinstance(k, (int, np.integer)):
        kk: Any = slice(max(k - 3, 0), k + 1)  # intervals k − 3 … k (a sample's t_d)
    else:  # rebuilt intervals (relin): their neighbours too (a sample's t_d may move)
        ks = np.asarray(k, dtype=int)
        kk = np.unique(np.clip((ks[:, None] + np.arange(-3, 2)).ravel(), 0, nk - 2))
    st.accel_t[kk] = nav_accel(P, pos[kk], vel[kk], None if dg is None else dg[kk])
    return st


def lin_values(k: int, st: gf.KeyframeStates, bias: Any) -> Any:
    """Linearisation point of X(k), X(k+1) and B(k) (``bias``: accel and gyro)."""
    lin = gtsam.Values()
    lin.insert(X(k), gtsam.Pose3(gtsam.Rot3(st.rot[k]), st.pos[k]))
    lin.insert(X(k + 1), gtsam.Pose3(gtsam.Rot3(st.rot[k + 1]), st.pos[k + 1]))
    lin.insert(B(k), gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6]))
    return lin


def gnss_factor(P: Problem, k: int, st: gf.KeyframeStates, bias: Any, g_idx: Any) -> Any:
    """The GNSS fixes ``g_idx`` of interval k (strictly inside it; with the GNSS height
    state also the one on keyframe k+1) as one LinearContainerFactor on X(k), X(k+1) and
    B(k) (the accelerometer-bias columns of the interpolant included), and G(k), G(k+1)
    with the GNSS error state, linearised at ``st`` (``keyframe_states``; X(k+1): its
    prediction)."""
    return gnss_factors(P, [k], st, bias, [g_idx])[0]


def gnss_factors(P: Problem, ks: list[int], st: gf.KeyframeStates, bias: Any,
                 fixes: list[Any]) -> list[Any]:
    """``gnss_factor`` of several intervals ``ks`` (fixes ``fixes[i]`` in interval
    ``ks[i]``) with one row evaluation; None for an interval without fixes."""
    return [None if rows is None else _gnss_lcf(P, int(k), st, bias, *rows)
            for k, rows in zip(ks, gnss_interval_rows(P, ks, st, fixes), strict=True)]


def gnss_interval_rows(P: Problem, ks: list[int], st: gf.KeyframeStates,
                       fixes: list[Any]) -> list[tuple[Any, Any] | None]:
    """The whitened, reweighted GNSS rows (r, J) of each interval ``ks[i]`` (its fixes
    ``fixes[i]``; position rows, then velocity rows) from one row evaluation; None for an
    interval without fixes."""
    n_of = np.array([f.size for f in fixes], dtype=int)
    out: list[Any] = [None] * len(ks)
    if not n_of.sum():
        return out
    g_idx = np.concatenate(fixes).astype(int)
    cfg, thr = P.cfg, P.cfg.loss_threshold_sd
    rows = gf.gnss_rows(
        P.dense, st, P.g_t[g_idx], P.g_pos[g_idx], P.g_pos_sd[g_idx],
        None if P.g_vel is None else P.g_vel[g_idx],
        None if P.g_vel_sd is None else P.g_vel_sd[g_idx], P.lever,
        k=np.repeat(np.asarray(ks, dtype=int), n_of),
        omega_b=None if P.g_omega is None else P.g_omega[g_idx])
    n = 3 * g_idx.size  # position rows, then velocity rows
    # per fix (3 rows each, position then velocity): its reweighted rows
    r_parts, j_parts = [], []
    for sl, loss, kk in ((slice(0, n), cfg.loss_gnss_pos, thr[0]),
                         (slice(n, None), cfg.loss_gnss_vel, thr[1])):
        if rows.r[sl].size:
            rw, jw, _, _ = reweight(rows.r[sl], rows.jac[sl], 3, loss, kk)
            r_parts.append(rw.reshape(-1, 3))
            j_parts.append(jw.reshape(-1, 3, jw.shape[1]))
    ends = np.cumsum(n_of)
    for i in range(len(ks)):
        if not n_of[i]:
            continue
        f0, f1 = int(ends[i] - n_of[i]), int(ends[i])
        r = np.concatenate([rp[f0:f1].ravel() for rp in r_parts])
        jac = np.vstack([jp[f0:f1].reshape(-1, jp.shape[2]) for jp in j_parts])
        out[i] = (r, jac)
    return out


def _gnss_lcf(P: Problem, k: int, st: gf.KeyframeStates, bias: Any, r: Any, jac: Any) -> Any:
    """Interval k's whitened GNSS rows (r, J) as its LinearContainerFactor."""
    lin = lin_values(k, st, bias)
    if P.gm is not None:  # five keys: from the information, as the baro terms
        rows_g = gf.IntervalRows(np.zeros(r.size, dtype=np.intp), r, jac)
        _, lam, eta, _ = gf.group_information(rows_g)
        # X_k, X_k+1, b_a (+ 3 zero gyro columns), G_k, G_k+1
        d = P.gm.dim
        lam_p, eta_p = pad_information(lam[0], eta[0],
                                       np.r_[0:12, gf.COL_BA, gf.N_COLS:gf.n_cols_of(d)],
                                       np.r_[0:15, 18:18 + 2 * d], 18 + 2 * d)
        lin.insert(G(k), np.array(st.gnss_gm[k], ndmin=1))
        lin.insert(G(k + 1), np.array(st.gnss_gm[k + 1], ndmin=1))
        return container([X(k), X(k + 1), B(k), G(k), G(k + 1)], lam_p, eta_p,
                         gnss_gm_blocks(d), lin)
    # the same information in ≤ 16 rows (QR of [J | r] over X(k), X(k+1), b_a): 9 fixes
    # with velocity are 54 rows; kept whole they held ~200 MB more on a 1-hour drive
    a_r = np.hstack([jac[:, gf.COL_X0], jac[:, gf.COL_X1], jac[:, gf.COL_BA], r[:, None]])
    if a_r.shape[0] > a_r.shape[1]:
        a_r = np.linalg.qr(a_r, mode="r")
    n_r = a_r.shape[0]
    j_b = np.hstack([a_r[:, 12:15], np.zeros((n_r, 3))])  # (accel, gyro)
    jf = gtsam.JacobianFactor(X(k), a_r[:, 0:6], X(k + 1), a_r[:, 6:12], B(k), j_b,
                              -a_r[:, 15], gtsam.noiseModel.Unit.Create(n_r))
    return gtsam.LinearContainerFactor(jf, lin)


def baro_factors(P: Problem, k: int, st: gf.KeyframeStates, bias: Any, cal: dict[int, Any],
                 seg: Any, bt: Any, bz: Any, baro_next: int, pri: dict[str, float],
                 last: bool = False) -> tuple[list[tuple[int, np.ndarray, Any]], int]:
    """The baro samples stamped since the last update, up to t_{k+1} (all of them when
    ``last``), as one LinearContainerFactor per interval of their delayed time
    t_s − τd (``baro_terms``), and the index of the next sample to take. A sample stamped
    by t_{k+1} has its delayed time before it, so it never waits: the online estimate of
    keyframe k+1 has every sample that has arrived."""
    if P.drive.baro is None:
        return [], baro_next
    tau_now = float(cal[int(seg[k])][1])
    # arrived (t_s ≤ t_{k+1}) and delayed into an existing interval (t_s − τd < t_{k+1}:
    # with a negative τd a sample waits for its keyframe)
    stop = bt.size if last else min(
        int(np.searchsorted(bt, P.t_kf[k + 1], side="right")),
        int(np.searchsorted(bt - tau_now, P.t_kf[k + 1], side="left")))
    sel = np.arange(baro_next, stop)
    baro_next = max(stop, baro_next)
    sel = sel[bt[sel] - tau_now >= P.t_kf[0] - 1.0]
    if not sel.size:
        return [], baro_next
    return baro_terms(P, k, st, bias, cal, seg, bt, bz, sel, pri, lag=tau_now), baro_next


def baro_terms(P: Problem, k: int, st: gf.KeyframeStates, bias: Any, cal: dict[int, Any],
               seg: Any, bt: Any, bz: Any, sel: np.ndarray, pri: dict[str, float],
               lag: float | None = None, extra: dict[int, Any] | None = None,
               floor: int = 0) -> list[tuple[int, np.ndarray, Any]]:
    """Baro samples ``sel`` linearised at ``st`` (keyframe k+1: its prediction) with each
    keyframe's segment calibration (later segments: the newest, K(seg[k])): one
    (interval m, its samples, LinearContainerFactor) per interval of their delayed time
    t_s − τd, on X(m), X(m+1), C(m), C(m+1), K(j) and B(m) (accelerometer-bias columns
    included). ``lag``: the time the bias is read before t_s (default: each sample's τd of
    this linearisation, as in the batch solve). ``extra``: more rows (r, J) in the same
    columns by interval (the GNSS rows of a rebuilt interval, ``relin``), summed into that
    interval's factor (one without baro samples if it has none). ``floor``: the first
    keyframe iSAM2 still holds (``window``); a sample whose delayed time moved before it
    (τd grew since it entered) is left out: its interval's keys have left iSAM2, and a factor
    on them failed the update ("key b599 does not exist")."""
    cfg, ks = P.cfg, P.cfg.loss_threshold_sd
    j_now = int(seg[k])
    # each keyframe's (s, τd): its segment's current estimate (later ones: the newest)
    seg_c = np.minimum(seg, j_now)
    s_kf = np.array([cal[int(j)][0] for j in range(j_now + 1)])[seg_c]
    tau_kf = np.array([cal[int(j)][1] for j in range(j_now + 1)])[seg_c]
    st = dataclasses.replace(st, scale=s_kf, latency=tau_kf)
    bias_lag: Any = (tau_kf[gf.interval_of(P.t_kf, bt[sel])] if lag is None else lag)
    rows = gf.baro_rows(P.dense, st, bt[sel], bz[sel], pri["noise"], P.h0, P.origin,
                        bias_lag=bias_lag)
    if floor > 0 and np.any(rows.k < floor):
        keep = rows.k >= floor
        rows = gf.IntervalRows(rows.k[keep], rows.r[keep], rows.jac[keep])
        sel = sel[keep]
        if not sel.size and not extra:
            return []
    # delayed times past the newest keyframe (none but at the end) are clipped into it
    m_of = np.minimum(rows.k, k)
    # robust losses: IRLS weights at this linearisation (one per sample)
    rw, jw, _, _ = reweight(rows.r, rows.jac, 1, cfg.loss_baro, ks[2])
    m_all = m_of
    if extra:
        m_all = np.concatenate([m_of] + [np.full(r.size, m, dtype=m_of.dtype)
                                         for m, (r, _) in extra.items()])
        rw = np.concatenate([rw] + [r for r, _ in extra.values()])
        jw = np.vstack([jw] + [j for _, j in extra.values()])
    groups, lam, eta, _ = gf.group_information(gf.IntervalRows(m_all, rw, jw))
    ms = [int(m) for m in groups]
    lin = _baro_lin(ms, st, bias, cal, seg)
    # each interval's samples, in their order in ``sel``
    by_m = np.argsort(m_of, kind="stable")
    cuts = np.searchsorted(m_of[by_m], np.r_[groups, groups + 1])
    cols = np.arange(gf.N_COLS)
    lam_p, eta_p = pad_information(lam, eta, cols, cols, gf.N_COLS + 3)
    keys_of = [[X(m), X(m + 1), C(m), C(m + 1), K(int(seg[m])), B(m)] for m in ms]
    facs = containers(keys_of, lam_p, eta_p, BARO_BLOCKS, lin)
    return [(m, sel[by_m[cuts[i]:cuts[i + len(ms)]]], facs[i]) for i, m in enumerate(ms)]


def _baro_lin(ms: list[int], st: gf.KeyframeStates, bias: Any, cal: dict[int, Any],
              seg: Any) -> Any:
    """One linearisation point holding the keys of the baro factors of intervals ``ms``
    (a LinearContainerFactor copies only its own keys from it): each shared keyframe's
    pose built once instead of once per factor."""
    lin = gtsam.Values()
    for k in sorted(set(ms) | {m + 1 for m in ms}):
        lin.insert(X(k), gtsam.Pose3(gtsam.Rot3(st.rot[k]), st.pos[k]))
        lin.insert(C(k), np.array([st.baro_bias[k]]))
    for m in ms:
        lin.insert(B(m), gtsam.imuBias.ConstantBias(bias[m, 0:3], bias[m, 3:6]))
    for j in sorted({int(seg[m]) for m in ms}):
        lin.insert(K(j), np.asarray(cal[j], float))
    return lin
