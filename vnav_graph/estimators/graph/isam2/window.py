"""A bounded memory for ``graph-isam2``: old keyframes leave iSAM2, the smoothed estimate
still covers the whole drive (``GraphConfig.isam2_window_s``).

iSAM2 keeps the Bayes tree of every keyframe it has seen: about 140 KB per keyframe with the
interval terms (QR elimination stores each clique's stacked rows twice), ≈ 500 MB for a
1-hour drive and 4.7 GB for 6 hours, and its per-update cost grows with the drive.
:class:`Window` bounds both. Once the online pass is ``isam2_window_s`` past a keyframe, that
keyframe's variables (X, V, B, C, G, and the segment calibrations K, A whose segments lie
wholly before it) leave iSAM2, in chunks of a tenth of the window: the factors that touch
them are replaced by their linear marginal on the neighbours (``Window.marginalise`` says
why this is not ``ISAM2.marginalizeLeaves`` alone).

What is marginalised is not forgotten. Before iSAM2 drops the variables ``L``, the factors
that touch them, linearised at iSAM2's linearisation point, are eliminated here in ``L``'s
order: the conditional p(L | S) of the square-root information smoother, S the
neighbours. The posterior factors exactly as p(L | S) times what iSAM2 keeps, so after the
last update the smoothed estimate of ``L`` is one back-substitution away: newest group first,
δ_L = R⁻¹(d − S·δ_S) with δ_S the final estimate of the neighbours in the local coordinates
of their linearisation point at marginalisation. This is the full smoother of the
linearised problem (RTS in square-root form), not a fixed-lag estimate; what differs from
keeping every keyframe is only that the old keyframes are not relinearised again after they
leave (their last linearisation is the one ``isam2_window_s`` of later data converged).
The neighbours stay relinearisable (the marginal, a ``LinearContainerFactor``, re-centres
itself), and the interval terms of keyframes that left are no longer rebuilt
(``relin.TermBook.freeze``), nor can the post-solve gate remove their fixes.

Each conditional is kept as numpy arrays (R, S, d: ≈ 6 KB per keyframe, 20 MB for a
1-hour drive); GTSAM's own conditionals keep a copy of the stacked rows they came from.
A weakly observable state whose online estimate is still far off when it leaves the window
is where this can fail (a 30 s window on the vertical test problem, heading held only by
the accelerometer biases: the heading 0.5° from the optimum); graph-isam2's batch check
then returns the batch pass with a warning, as for any iSAM2 estimate that is not the
optimum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ..model.extend import prior_factor, read_value, tangent_dim
from ..model.problem import Problem

# marginalise in chunks of this fraction of the window: one elimination per chunk
CHUNK_FRACTION = 0.1


@dataclass
class _Conditional:
    key: int
    r: np.ndarray  # (d, d) upper triangular
    s: np.ndarray  # (d, Σ parent dims)
    d: np.ndarray
    parents: tuple[int, ...]


class Window:
    """The window of keyframes iSAM2 holds, and the conditionals of the ones it dropped
    (module docstring). ``first``: the oldest keyframe still in iSAM2."""

    def __init__(self, P: Problem, seg: np.ndarray, window_s: float, ext: Any) -> None:
        t = P.t_kf
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        self.P = P
        self.seg = seg
        self.window_s = float(window_s)
        self.w = max(int(math.ceil(window_s / dt)), 2)
        self.chunk = max(int(self.w * CHUNK_FRACTION), 1)
        self.first = 0
        self.first_seg = 0  # the oldest segment whose K / A is still in iSAM2
        self.groups: list[tuple[list[_Conditional], dict[int, Any]]] = []
        self.marginalised = 0
        self.reeliminated = 0  # variables iSAM2 re-eliminated for the marginals
        self.ext_vars = ({key: var for key, (var, _) in ext.variables.items()}
                         if ext is not None else {})
        # a user factor enters with the last keyframe it touches: the keyframes it touches
        # must still be in iSAM2 then (hold[k]: the oldest keyframe touched by a factor
        # still to enter after the update that creates keyframe k, i.e. with ready > k)
        n = P.n_kf
        lo_at = np.full(n + 2, n, dtype=np.int64)  # per ready keyframe: its factors' oldest
        if ext is not None:
            for f, ready in zip(ext.factors, ext.ready, strict=True):
                lo = min((int(gtsam.Symbol(k).index()) for k in f.keys()
                          if int(k) not in ext.variables), default=ready)
                lo_at[ready] = min(lo_at[ready], lo)
        self.hold = np.minimum.accumulate(lo_at[::-1])[::-1][1:]  # min over ready > k

    # -- which keys ----------------------------------------------------------------------

    def _keys(self, m0: int, m1: int, b_last: int) -> list[int]:
        """Keys of keyframes m0..m1−1 in time order, then the calibrations of the segments
        that end before m1."""
        P = self.P
        has_baro, has_gm = P.drive.baro is not None, P.gm is not None
        keys: list[int] = []
        for m in range(m0, m1):
            keys += [X(m), V(m)]
            if m <= b_last:
                keys.append(B(m))
            if has_baro:
                keys.append(C(m))
            if has_gm:
                keys.append(G(m))
        j1 = int(self.seg[m1])  # segments before keyframe m1's are wholly before it
        for j in range(self.first_seg, j1):
            if has_baro:
                keys.append(K(j))
            if P.ka is not None:
                keys.append(A(j))
        return keys

    def due(self, k_new: int) -> int:
        """The keyframe the window would start at after the update that created ``k_new``
        (``first`` when nothing leaves yet)."""
        m1 = min(k_new - self.w, int(self.hold[k_new]))
        return m1 if m1 - self.first >= self.chunk else self.first

    # -- values of any key ---------------------------------------------------------------

    def _read(self, vals: Any, key: int) -> Any:
        ch = chr(gtsam.Symbol(key).chr())
        if ch == "x":
            return vals.atPose3(key)
        if ch == "b":
            return vals.atConstantBias(key)
        if key in self.ext_vars:
            return read_value(vals, self.ext_vars[key])
        return np.asarray(vals.atVector(key), float)

    @staticmethod
    def _local(lin: Any, now: Any) -> np.ndarray:
        if isinstance(lin, np.ndarray):
            return now - lin
        if isinstance(lin, gtsam.imuBias.ConstantBias):
            return now.vector() - lin.vector()
        return lin.localCoordinates(now)

    @staticmethod
    def _retract(lin: Any, d: np.ndarray) -> Any:
        if isinstance(lin, np.ndarray):
            return lin + d
        if isinstance(lin, gtsam.imuBias.ConstantBias):
            v = lin.vector() + d
            return gtsam.imuBias.ConstantBias(v[0:3], v[3:6])
        return lin.retract(d)

    # -- marginalisation -----------------------------------------------------------------

    def marginalise(self, isam: Any, m1: int, b_last: int) -> list[int]:
        """Keyframes ``first``..m1−1 (and the segment calibrations wholly before m1) leave
        iSAM2; their conditional given their neighbours is kept. Returns the iSAM2 indices
        of the factors that went with them.

        The marginalisation is done here, not by ``ISAM2.marginalizeLeaves`` alone: that
        needs whole leaf cliques, and when a clique held both a leaving and a staying
        keyframe it removed the staying keyframe's IMU factor from iSAM2's graph (its
        information then lived only in the tree). Here the factors that touch the leaving
        variables are replaced by their marginal on the neighbours (``LinearContainerFactor``s
        at iSAM2's linearisation point), which iSAM2 re-eliminates like any new factor; the
        leaving variables, then held by a unit prior each, are single-variable root cliques
        that ``marginalizeLeaves`` removes cleanly."""
        keys = self._keys(self.first, m1, b_last)
        vi = isam.getVariableIndex()
        idx = sorted({int(i) for key in keys for i in vi.at(key)})
        graph = isam.getFactorsUnsafe()
        lin = isam.getLinearizationPoint()
        gfg = gtsam.GaussianFactorGraph()
        for i in idx:
            gfg.push_back(graph.at(i).linearize(lin))
        order = gtsam.Ordering()
        for key in keys:
            order.push_back(key)
        bn, rest = gfg.eliminatePartialSequential(order)
        conds = []
        needed: set[int] = set()
        for i in range(bn.size()):
            c = bn.at(i)
            ks = [int(k) for k in c.keys()]
            conds.append(_Conditional(ks[0], np.array(c.R()), np.array(c.S()),
                                      np.array(c.d()), tuple(ks[1:])))
            needed.update(ks)
        self.groups.append((conds, {key: self._read(lin, key) for key in needed}))
        nf = gtsam.NonlinearFactorGraph()
        for i in range(rest.size()):
            f = rest.at(i)
            if f is not None and not f.empty():
                nf.add(gtsam.LinearContainerFactor(f, lin))
        # the marginal's variables stay relinearisable (the LinearContainerFactor re-centres
        # it): holding them at ``lin``, as ISAM2.marginalizeLeaves does, left the heading of
        # the vertical test problem (30 s window, heading weakly held) 19° off the optimum
        # instead of 0.5°
        for key in keys:
            nf.add(self._unit_prior(lin, key))
        del bn, rest, gfg, graph, vi
        # plain COLAMD over what is re-eliminated (iSAM2's default would put every key of
        # the marginal, i.e. the window's oldest keyframe, in the root clique)
        res = isam.update(nf, gtsam.Values(), idx, gtsam.KeyGroupMap())
        leaves = gtsam.KeyList()
        for key in keys:
            leaves.push_back(key)
        _, deleted = isam.marginalizeLeavesWithIndices(leaves)
        self.marginalised += m1 - self.first
        self.first = m1
        self.first_seg = int(self.seg[m1])
        self.reeliminated += int(res.getVariablesReeliminated())
        return idx + [int(i) for i in deleted]

    def _unit_prior(self, lin: Any, key: int) -> Any:
        v = self._read(lin, key)
        return prior_factor(key, v, gtsam.noiseModel.Unit.Create(tangent_dim(v)))

    def info(self) -> dict[str, Any]:
        """What ``Estimate.info`` reports about the window."""
        return {"isam2_window_s": self.window_s, "isam2_window_keyframes": self.w,
                "isam2_marginalised_keyframes": self.marginalised,
                "isam2_marginalisation_reeliminated": self.reeliminated}

    # -- the smoothed estimate -----------------------------------------------------------

    def complete(self, est: Any) -> Any:
        """``est`` (iSAM2's estimate of the keys it holds) with the marginalised keys added
        by back-substitution, newest group first."""
        now: dict[int, Any] = {}

        def value(key: int) -> Any:
            if key not in now:
                now[key] = self._read(est, key)
            return now[key]

        for conds, lin in reversed(self.groups):
            delta: dict[int, np.ndarray] = {}
            for c in reversed(conds):  # the last eliminated has only neighbours as parents
                dp = [delta[p] if p in delta else self._local(lin[p], value(p))
                      for p in c.parents]
                rhs = c.d - (c.s @ np.concatenate(dp) if dp else 0.0)
                delta[c.key] = np.linalg.solve(c.r, rhs) if c.r.size else rhs
            for key, d in delta.items():
                x = self._retract(lin[key], d)
                now[key] = x
                est.insert(key, x)
        return est
