"""Relinearisation of ``graph-isam2``'s interval terms (baro samples, GNSS fixes between keyframes).

The terms are linearised in numpy (``factors``) and enter iSAM2 as one
``LinearContainerFactor`` (LCF) per keyframe interval, so that no Python callback runs inside
iSAM2 (a ``CustomFactor`` copies the whole ``Values`` at every evaluation). An LCF is a fixed
quadratic; this module keeps each one's linearisation point and its factor index and swaps
it for a fresh linearisation (``ISAM2.update(..., removeFactorIndices)``) when its variables
moved beyond the thresholds iSAM2 uses for its own factors:

- X(k), X(k+1) (rotation, translation of the Pose3 tangent) and B(k) (accelerometer bias):
  ``GraphConfig.relinearize_typed`` (or the scalar ``relinearize_threshold``). Candidates are
  the intervals touching a key iSAM2 marked in its last update (it marks the variables it
  relinearised and those of added/removed factors), so the check costs nothing between
  iSAM2's own relinearisation steps.
- K(j) = (s, τd): ``CALIB_THRESHOLD``. iSAM2 itself never relinearises K (only linear C++
  factors touch it), but the baro rows depend on it nonlinearly (h(t_s − τd), (1 + s)·h), so
  every interval of a segment whose K moved that far is relinearised.
- C(k) (baro bias) enters the rows linearly; V(k) only through the Coriolis term of the
  interpolant (2Ω×δv ≈ 7e-5 m/s² per m/s): neither triggers.

A relinearised LCF has all 19 columns of the rows (the five core blocks and B(k)'s
accelerometer part); robust losses are reweighted at every linearisation (IRLS). A baro
sample keeps the interval it was first assigned to (its delayed time at that τd); a later τd
clips its delayed time into that interval, except in ``final`` where all samples are
reassigned at the current τd (then the partition is the batch's).
"""

from __future__ import annotations

from functools import cache
from itertools import combinations
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, K, X

from . import factors as gf
from .problem import gravity_delta
from .robust import reweight

# relinearisation thresholds of the calibration K = (s, τd) for the interval terms: the
# linearisation error of (1 + s)·h is δs·δh (≤ 1 mm for δh ≤ 1 m), that of h(t_s − τd) is
# ½·a_up·δτ² (≤ 0.1 mm at 1 m/s²)
CALIB_THRESHOLD = (1e-2, 0.05)
# blocks of one interval factor: X_k (6), X_k+1 (6), C_k, C_k+1, K (2), B_k (6: accel, gyro)
BLOCKS6 = ((0, 6), (6, 6), (12, 1), (13, 1), (14, 2), (16, 6))
N6 = 22
_KEY_BITS = 56
_IDX_MASK = (1 << _KEY_BITS) - 1


@cache
def _cover(active: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """Triples of ``active`` blocks covering every pair (greedy)."""
    if len(active) <= 3:
        return (active,)
    todo = set(combinations(active, 2))
    out = []
    for tr in combinations(active, 3):
        pairs = set(combinations(tr, 2))
        if pairs & todo:
            out.append(tr)
            todo -= pairs
    return tuple(out)


def info_factor(keys: list[int], lam: np.ndarray, eta: np.ndarray,
                active: tuple[int, ...]) -> Any:
    """A JacobianFactor with information ``lam`` (22×22 over ``BLOCKS6``) and ``eta`` on the
    ``active`` blocks, assembled from ≤3-key HessianFactor pieces (each block pair, diagonal
    and gradient owned by exactly one piece, so the pieces sum to the whole)."""
    sl = [slice(a, a + n) for a, n in BLOCKS6]
    owned: set[tuple[int, int]] = set()
    gfg = gtsam.GaussianFactorGraph()
    for tr in _cover(active):
        g = {}
        vec = []
        for i, a in enumerate(tr):
            vec.append(eta[sl[a]] if (a, a) not in owned else np.zeros(BLOCKS6[a][1]))
            for b in tr[i:]:
                g[a, b] = (lam[sl[a], sl[b]] if (a, b) not in owned
                           else np.zeros((BLOCKS6[a][1], BLOCKS6[b][1])))
        owned.update(g)
        kk = [keys[a] for a in tr]
        if len(tr) == 3:
            a, b, c = tr
            f = gtsam.HessianFactor(kk[0], kk[1], kk[2], g[a, a], g[a, b], g[a, c], vec[0],
                                    g[b, b], g[b, c], vec[1], g[c, c], vec[2], 0.0)
        elif len(tr) == 2:
            a, b = tr
            f = gtsam.HessianFactor(kk[0], kk[1], g[a, a], g[a, b], vec[0], g[b, b], vec[1],
                                    0.0)
        else:
            (a,) = tr
            f = gtsam.HessianFactor(kk[0], g[a, a], vec[0], 0.0)
        gfg.push_back(f)
    return gtsam.JacobianFactor(gtsam.HessianFactor(gfg))


class IntervalTerms:
    """The interval LCFs of one iSAM2 pass: sample sets, linearisation points, factor
    indices; builds, checks and swaps them (module docstring)."""

    def __init__(self, P: Any, seg: np.ndarray, cfg: Any) -> None:
        self.P = P
        self.seg = seg
        self.has_baro = P.drive.baro is not None
        nk = P.n_kf
        n = max(nk - 1, 0)
        self.bt = P.drive.baro.t if self.has_baro else np.zeros(0)
        self.bz = P.drive.baro.altitude if self.has_baro else np.zeros(0)
        self.baro_next = 0
        self.baro_of: list[np.ndarray] = [np.zeros(0, dtype=int)] * n
        g_between = np.flatnonzero((P.g_kf == -1) & P.g_use)
        gk = gf.interval_of(P.t_kf, P.g_t[g_between])
        self.gnss_of = [g_between[gk == k] for k in range(n)]
        self.index = np.full(n, -1, dtype=np.int64)  # iSAM2 factor index, -1: none
        self.lin_rot = np.zeros((n, 2, 3, 3))
        self.lin_pos = np.zeros((n, 2, 3))
        self.lin_ba = np.zeros((n, 3))
        self.lin_cal = np.zeros((n, 2))
        if cfg.relinearize_threshold <= 0:
            self.thr = None
        elif cfg.relinearize_typed is None:
            t = cfg.relinearize_threshold
            self.thr = (t, t, t)
        else:
            rot, trans, _, ba, _ = cfg.relinearize_typed
            self.thr = (rot, trans, ba)
        self.relinearized = 0  # swaps done
        self.pending: list[int] = []

    # -- building ------------------------------------------------------------------------

    def assign_baro(self, k: int, tau: float, last: bool) -> None:
        """Baro samples of interval k: those whose delayed time t_s − τd (τd now) falls in it
        (all the rest for the last interval)."""
        P = self.P
        if not self.has_baro:
            return
        t_end = P.t_kf[k + 1] if not last else np.inf
        stop = int(np.searchsorted(self.bt - tau, t_end, side="left"))
        sel = np.arange(self.baro_next, stop)
        self.baro_of[k] = sel[(self.bt[sel] - tau >= P.t_kf[0] - 1.0)]
        self.baro_next = max(stop, self.baro_next)

    def factors(self, ks: list[int], rot: Any, pos: Any, vel: Any, bias: Any, cb: Any,
                cal_of: Any) -> list[Any]:
        """Fresh LCFs of intervals ``ks`` at the states given (keyframe arrays; ``cal_of(j)``
        the calibration of segment j); records their linearisation points. One vectorised
        row evaluation for all of them. An interval without terms gives None."""
        if not ks:
            return []
        P, pri, cfg = self.P, self.P.pri, self.P.cfg
        ks_thr = cfg.loss_threshold_sd
        nk = P.n_kf
        ks_arr = np.asarray(ks, dtype=int)
        segs = self.seg[ks_arr]
        cals = np.array([np.asarray(cal_of(int(j)), float) for j in segs]) if self.has_baro \
            else np.zeros((len(ks), 2))
        scale = np.zeros(nk)
        lat = np.zeros(nk)
        scale[ks_arr], lat[ks_arr] = cals[:, 0], cals[:, 1]
        acc = np.tile(np.array([0.0, 0.0, P.g0]), (nk, 1))
        acc[ks_arr] += gravity_delta(P, pos[ks_arr]) - 2 * np.cross(P.omega_t, vel[ks_arr])
        st = gf.KeyframeStates(rot, pos, vel, bias[:, 0:3], cb, scale, lat, acc)
        parts = []
        if self.has_baro:
            sel = [self.baro_of[k] for k in ks]
            idx = np.concatenate(sel) if sel else np.zeros(0, dtype=int)
            if idx.size:
                kk = np.repeat(ks_arr, [s.size for s in sel])
                # the bias is read at t_s − τd of this linearisation, as in the batch solve
                lag = lat[kk]
                rows = gf.baro_rows(P.dense, st, self.bt[idx], self.bz[idx], pri["noise"],
                                    P.h0, P.origin, bias_lag=lag, interval=kk)
                rw, jw, _, _ = reweight(rows.r, rows.jac, 1, cfg.loss_baro, ks_thr[2])
                parts.append(gf.IntervalRows(kk, rw, jw))
        g_idx = np.concatenate([self.gnss_of[k] for k in ks]) if ks else np.zeros(0, int)
        if g_idx.size:
            rows = gf.gnss_rows(
                P.dense, st, P.g_t[g_idx], P.g_pos[g_idx], P.g_pos_sd[g_idx],
                None if P.g_vel is None else P.g_vel[g_idx],
                None if P.g_vel_sd is None else P.g_vel_sd[g_idx], P.lever)
            n = 3 * g_idx.size  # position rows, then velocity rows
            for sl, loss, kt in ((slice(0, n), cfg.loss_gnss_pos, ks_thr[0]),
                                 (slice(n, None), cfg.loss_gnss_vel, ks_thr[1])):
                if rows.r[sl].size:
                    rw, jw, _, _ = reweight(rows.r[sl], rows.jac[sl], 3, loss, kt)
                    parts.append(gf.IntervalRows(rows.k[sl], rw, jw))
        out: list[Any] = [None] * len(ks)
        if not parts:
            return out
        groups, lam19, eta19, _ = gf.group_information(gf.concat_rows(*parts), 1)
        where = {int(k): i for i, k in enumerate(ks)}
        active = (0, 1, 2, 3, 4, 5) if self.has_baro else (0, 1, 5)
        for g_i, k in enumerate(groups):
            k = int(k)
            i = where[k]
            lam = np.zeros((N6, N6))
            eta = np.zeros(N6)
            lam[:19, :19] = lam19[g_i]
            eta[:19] = eta19[g_i]
            # 1e-9 information (σ ≈ 3e4 in any unit, also on the unused gyro-bias columns)
            # makes the block positive definite so that it can be turned into a Jacobian
            lam += 1e-9 * np.eye(N6)
            j = int(segs[i])
            keys = [X(k), X(k + 1), C(k), C(k + 1), K(j), B(k)]
            lin = gtsam.Values()
            lin.insert(X(k), gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k]))
            lin.insert(X(k + 1), gtsam.Pose3(gtsam.Rot3(rot[k + 1]), pos[k + 1]))
            lin.insert(B(k), gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6]))
            if self.has_baro:
                lin.insert(C(k), np.array([cb[k]]))
                lin.insert(C(k + 1), np.array([cb[k + 1]]))
                lin.insert(K(j), cals[i])
            out[i] = gtsam.LinearContainerFactor(info_factor(keys, lam, eta, active), lin)
            self.lin_rot[k] = rot[k:k + 2]
            self.lin_pos[k] = pos[k:k + 2]
            self.lin_ba[k] = bias[k, 0:3]
            self.lin_cal[k] = cals[i]
        return out

    # -- relinearisation policy ----------------------------------------------------------

    def due(self, ks: np.ndarray, rot: Any, pos: Any, bias: Any, cal_seg: Any) -> np.ndarray:
        """Of the intervals ``ks`` that have a factor, those whose X(k), X(k+1), B(k) (in
        ``rot``, ``pos``, ``bias``: keyframe arrays holding the current estimate at least at
        these keyframes) or K (``cal_seg``: per segment) moved beyond the thresholds since
        their linearisation."""
        if self.thr is None or ks.size == 0:
            return ks[:0]
        ks = ks[self.index[ks] >= 0]
        rot_thr, trans_thr, ba_thr = self.thr
        r_lin = self.lin_rot[ks]
        r_now = np.stack([rot[ks], rot[ks + 1]], axis=1)
        # Pose3 local coordinates: rotation angle of R_linᵀR, translation R_linᵀ(p − p_lin)
        d_r = np.einsum("nkji,nkjl->nkil", r_lin, r_now)
        cosang = np.clip((np.einsum("nkii->nk", d_r) - 1.0) / 2.0, -1.0, 1.0)
        ang = np.arccos(cosang)
        p_now = np.stack([pos[ks], pos[ks + 1]], axis=1)
        d_p = np.einsum("nkji,nkj->nki", r_lin, p_now - self.lin_pos[ks])
        bad = (ang > rot_thr).any(1) | (np.abs(d_p) > trans_thr).any((1, 2))
        bad |= (np.abs(bias[ks, 0:3] - self.lin_ba[ks]) > ba_thr).any(1)
        if self.has_baro:
            d_c = np.abs(cal_seg[self.seg[ks]] - self.lin_cal[ks])
            bad |= (d_c > np.asarray(CALIB_THRESHOLD)).any(1)
        return ks[bad]

    def calib_due(self, n_made: int, cal_seg: np.ndarray) -> np.ndarray:
        """Intervals (of the first ``n_made``) whose segment's K moved beyond
        ``CALIB_THRESHOLD`` since their linearisation."""
        if self.thr is None or not self.has_baro or n_made == 0:
            return np.zeros(0, dtype=int)
        ks = np.arange(n_made)
        ks = ks[self.index[ks] >= 0]
        d_c = np.abs(cal_seg[self.seg[ks]] - self.lin_cal[ks])
        return ks[(d_c > np.asarray(CALIB_THRESHOLD)).any(1)]

    @staticmethod
    def marked_keyframes(keys: Any) -> np.ndarray:
        """Keyframe indices of the X/B keys in an ISAM2Result's marked keys."""
        arr = np.fromiter(keys, dtype=np.uint64)
        if arr.size == 0:
            return np.zeros(0, dtype=int)
        ch = (arr >> np.uint64(_KEY_BITS)).astype(int)
        idx = (arr & np.uint64(_IDX_MASK)).astype(int)
        return np.unique(idx[(ch == ord("x")) | (ch == ord("b"))])

    def candidates(self, marked: np.ndarray, n_made: int) -> np.ndarray:
        """Intervals (of the first ``n_made``) touching a marked keyframe."""
        ks = np.unique(np.r_[marked, marked - 1])
        return ks[(ks >= 0) & (ks < n_made)]
