"""Where ``graph-isam2``'s interval terms were linearised, when they are due and the (s, τd)
they are rebuilt at (``LinPoints``: the policy of ``relin.TermBook``, whose module docstring
says why)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model import interval_factors as gf
from ..model.problem import Problem

# relinearisation thresholds of K = (s, τd) for the interval terms: the linearisation error
# of (1 + s)·h is δs·δh (≤ 1 cm for δh ≤ 1 m at δs = 0.01), that of h(t_s − τd) is
# ½·a_up·δτ² (≤ 1.3 mm at 1 m/s² for δτ = 0.05 s)
CALIB_THRESHOLD = (1e-2, 0.05)


class LinPoints:
    """The linearisation point of each interval's terms over ``P`` (``seg``: segment of
    each keyframe): its keyframes' rotations and positions and its segment's K, from its
    first build until a rebuild; the thresholds; and per segment the (s, τd) its baro terms
    were last rebuilt at."""

    def __init__(self, P: Problem, seg: np.ndarray) -> None:
        cfg = P.cfg
        self.seg = seg
        n = max(P.n_kf - 1, 0)
        self.built = np.zeros(n, dtype=bool)
        self.lin_rot = np.zeros((n, 2, 3, 3))
        self.lin_pos = np.zeros((n, 2, 3))
        self.lin_cal = np.full((n, 2), np.nan)  # K of the interval's baro terms when built
        if cfg.relinearize_threshold <= 0:
            self.thr: tuple[float, float] | None = None
        elif cfg.relinearize_typed is None:
            self.thr = (cfg.relinearize_threshold, cfg.relinearize_threshold)
        else:
            self.thr = (cfg.relinearize_typed[0], cfg.relinearize_typed[1])
        # per segment: the (s, τd) its baro terms were last rebuilt at, and that rebuild's
        # step (``damped_calibration``)
        self.seg_lin: dict[int, np.ndarray] = {}
        self.seg_step: dict[int, np.ndarray] = {}
        self.damped = 0  # rebuilds whose (s, τd) step was halved

    def note(self, m: int, st: gf.KeyframeStates, cal: dict[int, Any] | None) -> None:
        """Interval m's linearisation point (kept from its first build until a rebuild; K
        from its first baro term)."""
        if not self.built[m]:
            self.built[m] = True
            self.lin_rot[m] = st.rot[m:m + 2]
            self.lin_pos[m] = st.pos[m:m + 2]
        if cal is not None and np.isnan(self.lin_cal[m, 0]):
            self.lin_cal[m] = cal[int(self.seg[m])]

    def clear(self, m: int) -> None:
        """Interval m's terms are being rebuilt: no point until they are noted again."""
        self.built[m] = False
        self.lin_cal[m] = np.nan

    def due(self, marked: np.ndarray, k_new: int, rot: Any, pos: Any,
            cal: dict[int, Any] | None, floor: int, all_segments: bool = False) -> np.ndarray:
        """Intervals to rebuild: among those touching a marked keyframe (``marked``), the
        ones whose keyframes (``rot``, ``pos``: current estimate there) moved beyond the
        thresholds; and the baro intervals of the newest two segments whose K moved beyond
        ``CALIB_THRESHOLD`` (of every segment with ``all_segments``). Only intervals from
        ``floor`` on, ending at or before keyframe ``k_new``."""
        if self.thr is None:
            return np.zeros(0, dtype=int)
        ks = np.unique(np.r_[marked, marked - 1]).astype(int)
        ks = ks[(ks >= floor) & (ks < k_new)]
        ks = ks[self.built[ks]]
        out = [np.zeros(0, dtype=int)]
        if ks.size:
            rot_thr, trans_thr = self.thr
            r_now = np.stack([rot[ks], rot[ks + 1]], axis=1)
            d_r = np.einsum("nkji,nkjl->nkil", self.lin_rot[ks], r_now)
            cosang = np.clip((np.einsum("nkii->nk", d_r) - 1.0) / 2.0, -1.0, 1.0)
            p_now = np.stack([pos[ks], pos[ks + 1]], axis=1)
            d_p = np.einsum("nkji,nkj->nki", self.lin_rot[ks], p_now - self.lin_pos[ks])
            bad = (np.arccos(cosang) > rot_thr).any(1) | (np.abs(d_p) > trans_thr).any((1, 2))
            out.append(ks[bad])
        if cal is not None and k_new >= 1:
            j_new = int(self.seg[k_new - 1])
            lo = 0 if all_segments else int(np.searchsorted(self.seg, max(j_new - 1, 0),
                                                            side="left"))
            m = np.arange(max(lo, floor), k_new)
            m = m[~np.isnan(self.lin_cal[m, 0])]
            if m.size:
                k_now = np.array([cal[int(j)] for j in self.seg[m]])
                bad = (np.abs(k_now - self.lin_cal[m]) > np.asarray(CALIB_THRESHOLD)).any(1)
                out.append(m[bad])
        return np.unique(np.concatenate(out))

    def damped_calibration(self, cal: dict[int, Any], ms: list[int]) -> dict[int, Any]:
        """The (s, τd) to rebuild the baro terms of intervals ``ms`` at: the estimate, except
        that a component whose step from the segment's last rebuild point reverses that
        rebuild's own step is moved half-way only. Rebuilding at the estimate is an undamped
        Gauss-Newton step in (s, τd); where h(t_s − τd) is strongly curved (a touchdown)
        and τd weakly determined, it alternates between two values and the final rounds
        never settle (docs/real_logs.md, "graph-isam2 on the shared logs"). Halving a
        reversed step damps such a cycle; monotone steps are taken whole."""
        out = dict(cal)
        for j in sorted({int(self.seg[m]) for m in ms}):
            now = np.asarray(cal[j], float)
            if j not in self.seg_lin:
                lin = self.lin_cal[[m for m in ms if int(self.seg[m]) == j]]
                lin = lin[~np.isnan(lin[:, 0])]
                if not lin.size:
                    continue
                self.seg_lin[j] = lin[0].copy()
            d = now - self.seg_lin[j]
            prev = self.seg_step.get(j)
            if prev is not None:
                rev = d * prev < 0
                if rev.any():
                    d = np.where(rev, 0.5 * d, d)
                    self.damped += 1
            self.seg_step[j] = d
            self.seg_lin[j] = self.seg_lin[j] + d
            out[j] = self.seg_lin[j].copy()
        return out
