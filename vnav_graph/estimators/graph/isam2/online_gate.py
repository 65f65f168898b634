"""graph-isam2's post-solve GNSS gate inside the online pass (``GraphConfig.isam2_gate_s``).

The batch's post-solve gate (``problem.post_solve_rejections``) refuses the fixes whose
whitened residual χ² *at the solution* exceeds the ``1 − (1 − p)²`` quantile, then solves
again. graph-batch on a drive cut at t (the filtering optimum of the online estimate) does
that over every fix up to t; without it the online pass weighs a multipath fix only by its
Huber weight at the prediction, and keeps it.

After each update the gate here takes the used fixes of the last ``isam2_gate_s`` seconds
still in iSAM2 and evaluates their χ² at iSAM2's current estimate with the batch's rule and
threshold. When some fail, the update first runs the relinearise-and-solve rounds of a GNSS
return (``OnlinePass._iterate``): the batch judges at a converged solution, and one
Gauss-Newton step is not one (after a 150 s IMU logging gap, judging after the single step
refused 503 of the next 520 fixes: the Huber-weighted fixes pulled too little, the refused
ones not at all, a lock-out). The fixes that still fail are refused (``P.g_use``) and the
update runs one more round without them. Causal: a fix is judged only with the data up to
the update. Like the batch's gate and the ekf's, a refusal is final: the final
rounds' gate adds to it and does not re-admit. As in the batch, nothing is refused when
every candidate fails (a solution that fits none of them is not one to judge them by).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model import interval_factors as gf
from ..model.problem import Problem, gate_failures
from . import linear_factors as terms
from .relin import TermBook


class OnlineGate:
    """The gate of one online pass and what it refused."""

    def __init__(self, P: Problem, span_s: float | None) -> None:
        self.P = P
        self.on = span_s is not None and span_s > 0 and P.cfg.gnss_gate_prob > 0
        self.span_s = float(span_s or 0.0)
        self.refused = 0  # fixes refused by the online gate
        self.rounds = 0  # solve rounds it ran (``OnlinePass._iterate``)

    def candidates(self, book: TermBook, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The used fixes iSAM2 holds after the update that created keyframe k + 1, from
        ``span_s`` before it; and the interval each one's rows are written on (≤ k)."""
        P = self.P
        t_hi = float(P.t_kf[k + 1])
        t_lo = max(t_hi - self.span_s, float(P.t_kf[book.floor]))
        idx = np.arange(np.searchsorted(P.g_t, t_lo, side="left"),
                        np.searchsorted(P.g_t, t_hi, side="right"))
        idx = idx[P.g_use[idx] & (P.g_kf[idx] >= -1)]
        m = np.minimum(gf.interval_of(P.t_kf, P.g_t[idx]), k)
        keep = m >= book.floor
        return idx[keep], m[keep]

    def judge(self, book: TermBook, k: int, arrays: tuple[Any, ...],
              dg_kf: Any) -> np.ndarray:
        """The candidate fixes (``candidates``) that fail the batch's gate
        (``problem.gate_failures``) at the running estimate ``arrays`` after the update that
        created keyframe k + 1; empty when none or every one fails, or when the gate is
        off."""
        if not self.on:
            return np.zeros(0, dtype=int)
        idx, m = self.candidates(book, k)
        if idx.size < 2:
            return idx[:0]
        st = terms.keyframe_states(self.P, np.unique(m).tolist(), *arrays, dg_kf)
        return gate_failures(self.P, st, idx, m)

    def refuse(self, book: TermBook, rej: np.ndarray) -> tuple[np.ndarray, list[int]]:
        """Refuse the fixes ``rej`` (``P.g_use``, ``P.g_rej_post``, ``refused``) and take
        them out of their intervals' terms (``TermBook.drop_fixes``); returns the intervals
        whose GNSS term must be rebuilt and the iSAM2 indices of the refused keyframe fixes'
        factors, to remove."""
        P = self.P
        P.g_use[rej] = False
        P.g_rej_post += int(rej.size)
        self.refused += int(rej.size)
        # a fix's interval, and with the GNSS error state a keyframe fix's (the one ending
        # at it)
        ms = set(gf.interval_of(P.t_kf, P.g_t[rej]).tolist()) \
            | {int(j) - 1 for j in P.g_kf[rej] if j >= 1}
        return book.drop_fixes(rej, sorted(m for m in ms if m < len(book.fixes_of)))
