"""graph-isam2's GNSS handling after each update of the online pass: the rounds when GNSS
returns, and the post-solve GNSS gate (``GraphConfig.isam2_gate_s``).

When GNSS returns after at least ``RETURN_GAP_S`` without a fix, the fix pulls the
dead-reckoned states metres to tens of metres, and one Gauss-Newton step from there leaves
the online estimate short of the filtering optimum (measured in docs/graph.md, "When GNSS
returns"): that update runs up to ``RETURN_ROUNDS`` more relinearise-and-solve rounds
(``OnlinePass.solve_rounds``).

The batch's post-solve gate (``problem.post_solve_rejections``) refuses the fixes whose
whitened residual χ² *at the solution* exceeds the ``1 − (1 − p)²`` quantile, then solves
again. graph-batch on a drive cut at t (the filtering optimum of the online estimate) does
that over every fix up to t; without it the online pass weighs a multipath fix only by its
Huber weight at the prediction, and keeps it.

After each update the gate here takes the used fixes of the last ``isam2_gate_s`` seconds
still in iSAM2 and evaluates their χ² at iSAM2's current estimate with the batch's rule and
threshold. When some fail, the update first runs the relinearise-and-solve rounds of a GNSS
return: the batch judges at a converged solution, and one Gauss-Newton step is not one
(after a 150 s IMU logging gap, judging after the single step refused 503 of the next 520
fixes: the Huber-weighted fixes pulled too little, the refused ones not at all, a
lock-out). The fixes that still fail are refused (``P.g_use``) and the
update runs one more round without them. Causal: a fix is judged only with the data up to
the update. Like the batch's gate and the ekf's, a refusal is final: the final
rounds' gate adds to it and does not re-admit. As in the batch, nothing is refused when
every candidate fails (a solution that fits none of them is not one to judge them by).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..model import interval_factors as gf
from ..model.problem import Problem, gate_failures
from . import linear_factors as terms
from .relin import TermBook

RETURN_GAP_S = 10.0  # [s] without a fix before a GNSS return
RETURN_ROUNDS = 5


class OnlineGate:
    """The GNSS returns and the gate of one online pass, and what they ran and refused."""

    def __init__(self, P: Problem, span_s: float | None) -> None:
        self.P = P
        self.on = span_s is not None and span_s > 0 and P.cfg.gnss_gate_prob > 0
        self.span_s = float(span_s or 0.0)
        self.refused = 0  # fixes refused by the online gate
        self.rounds = 0  # solve rounds it ran
        self.return_rounds = 0  # solve rounds run when GNSS returned
        self.last_fix_t = float(P.t_kf[0])  # the latest fix in an update so far

    def after_update(self, book: TermBook, k: int, fix_at: list[tuple[int, int]],
                     marked: np.ndarray, arrays: tuple[Any, ...], dg_kf: Any,
                     solve: Callable[..., tuple[np.ndarray, int]]) -> np.ndarray:
        """After the update that created keyframe k + 1 (``fix_at``: its keyframe fixes,
        ``marked``: the keyframes it marked): the rounds of a GNSS return, then the gate;
        ``solve(k, marked, rounds, gated, kf_rm)``: the pass's relinearise-and-solve rounds,
        returning the keyframes marked and the rounds run. Returns the keyframes marked."""
        if self.returns(book, k, fix_at):
            marked, n = solve(k, marked, RETURN_ROUNDS)
            self.return_rounds += n
        if self.judge(book, k, arrays, dg_kf).size:
            # converged first, as the batch's gate judges; then without what still fails
            marked, n = solve(k, marked, RETURN_ROUNDS)
            self.rounds += n
            bad = self.judge(book, k, arrays, dg_kf)
            if bad.size:
                gated, kf_rm = self.refuse(book, bad)
                marked, n = solve(k, marked, 1, gated, kf_rm)
                self.rounds += n
        return marked

    def returns(self, book: TermBook, k: int, fix_at: list[tuple[int, int]]) -> bool:
        """Whether update k holds the first GNSS fix after at least ``RETURN_GAP_S`` without
        one (keyframe k + 1's fixes and interval k's)."""
        idx = np.r_[np.asarray([i for i, _ in fix_at], dtype=int), book.fixes_of[k]]
        if not idx.size:
            return False
        t = self.P.g_t[idx.astype(int)]
        back = float(t.min()) - self.last_fix_t > RETURN_GAP_S
        self.last_fix_t = max(self.last_fix_t, float(t.max()))
        return back

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
