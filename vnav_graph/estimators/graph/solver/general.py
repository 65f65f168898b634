"""General sparse path of the batch solver: GTSAM's elimination of the linearised graph.

Used when the structure does not fit the banded arrow of ``layout`` (a factor linking
keyframes ≥ 2 apart, many extra variables), or when forced (``GraphConfig.solver =
"general"``). The linear system is the ``GaussianFactorGraph`` that ``graph.linearize`` returns
(every C++ factor, built-in or user-added), plus the interval terms of the custom baro/GNSS
rows as ≤3-key ``HessianFactor`` pieces of their per-interval information (``hessian_pieces``).
``GaussianFactorGraph.optimize`` eliminates it (multifrontal Cholesky) in a nested-dissection
ordering of the keyframe chain built once per solve (``elimination_ordering``);
the covariances from a sparse LU of the same normal equations (``GeneralCovariance``;
Dellaert & Kaess 2017 §3–4 for the elimination).
"""

from __future__ import annotations

from functools import cache
from itertools import combinations
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, G, K, X

from ....types.streams import FloatArray
from .layout import (
    IntervalInfo,
    Layout,
    SparsePattern,
    hessian_diagonal,
    jacobian_indices,
    sparse_pattern,
    template_keys,
)
from .linalg import trim_heap


def pair_cover(n: int) -> tuple[tuple[int, ...], ...]:
    """Triples of range(n) covering every pair (greedy: each new triple covers the most
    uncovered pairs)."""
    if n <= 3:
        return (tuple(range(n)),)
    todo = set(combinations(range(n), 2))
    out = []
    while todo:
        best = max(combinations(range(n), 3),
                   key=lambda t: sum(p in todo for p in combinations(t, 2)))
        out.append(best)
        todo -= set(combinations(best, 2))
    return tuple(out)


# interval-term key blocks in the padded column order of ``group_pieces``:
# X_k, X_k+1, [C_k, C_k+1, K(0),] B_k (6: the accel part of the rows, zero gyro part)
_BLOCKS_BARO = ((0, 6), (6, 6), (12, 1), (13, 1), (14, 2), (16, 6))
_BLOCKS_NO_BARO = ((0, 6), (6, 6), (12, 6))


@cache
def _cover(n: int) -> tuple[tuple[int, ...], ...]:
    return pair_cover(n)


def pad_information(lam: FloatArray, eta: FloatArray, src: np.ndarray, dst: np.ndarray,
                    n: int) -> tuple[FloatArray, FloatArray]:
    """Λ (…, c, c) and η (…, c) restricted to the columns ``src`` and placed at the columns
    ``dst`` of an n-column zero block: the key blocks' padded order (B_k's zero gyro-bias
    columns after its accelerometer part)."""
    lp = np.zeros(lam.shape[:-2] + (n, n))
    ep = np.zeros(eta.shape[:-1] + (n,))
    lp[..., dst[:, None], dst[None, :]] = lam[..., src[:, None], src[None, :]]
    ep[..., dst] = eta[..., src]
    return lp, ep


def _plan(blocks: tuple[tuple[int, int], ...], cover: tuple[tuple[int, ...], ...]
          ) -> list[tuple[tuple[int, ...], list[tuple[str, int, int]]]]:
    """The pieces of a pair cover: for each triple, the blocks it owns (each pair and
    diagonal block belongs to the first triple holding it) and its HessianFactor arguments
    in constructor order (G11, G12, [G13,] g1, G22, [G23,] g2, [G33, g3]): ("G", a, b) /
    ("g", a, a) for owned blocks, ("0G", a, b) / ("0g", a, a) for zeros. A block that the
    triple owns nothing of is left out (a 2-key piece)."""
    owned_pair: set[tuple[int, int]] = set()
    owned_diag: set[int] = set()
    plan = []
    for tr in cover:
        mine = {(a, b) for i, a in enumerate(tr) for b in tr[i + 1:]} - owned_pair
        used = tuple(b for b in tr if b not in owned_diag or any(b in p for p in mine))
        args = []
        for i, a in enumerate(used):
            for b in used[i:]:
                own = a not in owned_diag if a == b else (a, b) in mine
                args.append(("G" if own else "0G", a, b))
            args.append(("g" if a not in owned_diag else "0g", a, a))
        owned_pair |= mine
        owned_diag.update(tr)
        plan.append((used, args))
    return plan


def group_pieces(lay: Layout, info: IntervalInfo) -> list[Any]:
    """HessianFactor pieces of the interval information (Λ, η in ``term_cols`` order): the
    blocks of all intervals are sliced at once, then each triple of the pair cover becomes
    one 3-key ``HessianFactor`` per interval (≤ 3 keys: GTSAM's Python constructors)."""
    groups, lam, eta = info.groups, info.lam, info.eta
    g_n, c = lam.shape[0], lam.shape[1]
    n = c + 3  # + the zero gyro-bias columns of B_k
    n_gm = 2 * lay.gm_dim  # G_k, G_k+1: after B_k's zero gyro columns
    n_main = c - n_gm
    idx = np.r_[np.arange(n_main), n_main + 3 + np.arange(n_gm)]
    lam_p, eta_p = pad_information(lam, eta, np.arange(c), idx, n)
    blocks = _BLOCKS_BARO if lay.has_baro else _BLOCKS_NO_BARO
    if lay.has_gm:
        blocks = (*blocks, (n_main + 3, lay.gm_dim), (n_main + 3 + lay.gm_dim, lay.gm_dim))
    cover = _cover(len(blocks))
    sl = [slice(a, a + w) for a, w in blocks]
    plan = _plan(blocks, cover)
    # per triple: the (G, ·, ·) arrays of its constructor arguments
    arg_arrays = []
    for _, args in plan:
        arrs = []
        for kind, a, b in args:
            if kind == "G":
                arrs.append(np.ascontiguousarray(lam_p[:, sl[a], sl[b]]))
            elif kind == "g":
                arrs.append(np.ascontiguousarray(eta_p[:, sl[a]]))
            elif kind == "0G":
                arrs.append(np.zeros((g_n, blocks[a][1], blocks[b][1])))
            else:
                arrs.append(np.zeros((g_n, blocks[a][1])))
        arg_arrays.append(arrs)
    hf = gtsam.HessianFactor
    out = []
    for gi, k in enumerate(np.asarray(groups).tolist()):
        keys = ([X(k), X(k + 1), C(k), C(k + 1), K(0), B(k)] if lay.has_baro
                else [X(k), X(k + 1), B(k)])
        if lay.has_gm:
            keys += [G(k), G(k + 1)]
        for (tr, _), arrs in zip(plan, arg_arrays, strict=True):
            a = [x[gi] for x in arrs]
            if len(tr) == 3:
                out.append(hf(keys[tr[0]], keys[tr[1]], keys[tr[2]], a[0], a[1], a[2], a[3],
                              a[4], a[5], a[6], a[7], a[8], 0.0))
            elif len(tr) == 2:
                out.append(hf(keys[tr[0]], keys[tr[1]], a[0], a[1], a[2], a[3], a[4], 0.0))
            else:
                out.append(hf(keys[tr[0]], a[0], a[1], 0.0))
    return out


ND_LEAF = 8  # keyframes per leaf of the nested dissection (4–16 measured alike)


def dissection_order(a: int, b: int) -> list[int]:
    """Keyframes a … b−1 in nested-dissection order: both halves, then the middle one."""
    if b - a <= ND_LEAF:
        return list(range(a, b))
    m = (a + b) // 2
    return dissection_order(a, m) + dissection_order(m + 1, b) + [m]


def elimination_ordering(lay: Layout) -> Any:
    """Elimination ordering of the general path: nested dissection of the keyframe chain
    (the variables of one keyframe separate the intervals before it from those after it:
    every built-in factor links keyframes k and k+1), then every other variable (the
    globals, extensions' variables) in column order. Any ordering is exact; a factor that
    links distant keyframes only adds fill. The keys are the same at every Gauss-Newton
    iteration, so it is built once per solve (``Layout.ordering``). Measured on the 1-hour
    hill-drive (3601 keyframes, 32 405 factors), one solve: ``optimize()`` (COLAMD at every
    call) 0.36 s, METIS ordering 0.17 s (and METIS crashed on an extension's graph), this
    ordering 0.13 s; steps equal to 1.5e-9."""
    tmpl = template_keys(lay.nk, lay.has_baro, lay.gm_dim)
    per_kf = len(tmpl) // max(lay.nk, 1)
    o = gtsam.Ordering()
    for k in dissection_order(0, lay.nk):
        for key, _, _ in tmpl[k * per_kf:(k + 1) * per_kf]:
            if key in lay.key_cols:
                o.push_back(key)
    chain = {key for key, _, _ in tmpl}
    for key in sorted((key for key in lay.key_cols if key not in chain),
                      key=lambda key: lay.key_cols[key][0]):
        o.push_back(key)
    return o


class GeneralSystem:
    """The linearised graph plus the interval pieces, solved by GTSAM elimination."""

    def __init__(self, lay: Layout, cpp: Any, info: IntervalInfo) -> None:
        self.lay, self.cpp, self.info = lay, cpp, info
        self._gfg: Any = None
        self.damping = 0.0  # Marquardt damping a singular step needed (BandedSystem.damping)
        if lay.ordering is None:
            lay.ordering = elimination_ordering(lay)

    @property
    def gfg(self) -> Any:
        """The whole linear graph: the C++ factors plus the interval pieces as HessianFactors
        (built on first use; ``covariance`` releases it)."""
        if self._gfg is None:
            full = gtsam.GaussianFactorGraph()
            full.push_back(self.cpp)
            for f in group_pieces(self.lay, self.info):
                full.push_back(f)
            self._gfg = full
        return self._gfg

    def _diag(self) -> FloatArray:
        sj = self.cpp.sparseJacobian_()
        pat: SparsePattern = sparse_pattern(self.lay, *jacobian_indices(sj), cache=False)
        return hessian_diagonal(self.lay, pat, sj[2], self.info)

    def _solve_damped(self, mu: float, add: float = 0.0) -> Any:
        d = mu * self._diag() + add
        g2 = gtsam.GaussianFactorGraph()
        g2.push_back(self.gfg)
        unit = {}
        for key, (c, n) in self.lay.key_cols.items():
            if n not in unit:
                unit[n] = gtsam.noiseModel.Unit.Create(n)
            g2.push_back(gtsam.JacobianFactor(key, np.diag(np.sqrt(d[c:c + n])), np.zeros(n),
                                              unit[n]))
        return g2.optimize(self.lay.ordering)

    def step(self) -> tuple[Any, float]:
        """Gauss-Newton step (VectorValues) and the decrease ½ δᵀg it predicts (g = −∇ at 0);
        a numerically singular system is retried with growing Marquardt damping, as in the
        banded path."""
        try:
            delta = self.gfg.optimize(self.lay.ordering)
        except RuntimeError:
            delta = None
            for mu in (1e-9, 1e-7, 1e-5, 1e-3, 1e-1):
                try:
                    delta = self._solve_damped(mu, 1e-12)
                    self.damping = max(self.damping, mu)
                    break
                except RuntimeError:
                    continue
            if delta is None:
                raise RuntimeError(
                    "graph: the Gauss-Newton system stays singular even with Marquardt damping "
                    "1e-1·diag(H) — the drive does not determine the states (check IMU "
                    "rate/units and GNSS coverage)") from None
        return delta, -0.5 * float(delta.dot(self.gfg.gradientAtZero()))

    def release_factor(self) -> None:
        """Free the step's linear graph (rebuilt if a damped step needs it)."""
        self._gfg = None

    def damped(self, mu: float) -> Any:
        """Step of H + μ·diag(H) (Levenberg-Marquardt damping)."""
        return self._solve_damped(mu)

    def covariance(self) -> GeneralCovariance:
        # the step's graph is not needed for it (rebuilt if a step is asked for again): its
        # HessianFactor pieces are released before the factorisation, not alive under it
        self._gfg = None
        return GeneralCovariance(self.lay, self.cpp, self.info)


class GeneralCovariance:
    """Selected entries of H⁻¹ for the general path: H (the C++ rows' JᵀJ plus the interval
    blocks, in our columns) factorised once by a sparse LU (SuperLU with COLAMD ordering and
    no pivoting, i.e. a symmetric factorisation; scipy), then solved for the requested
    columns. ``gtsam.Marginals`` gives the
    same numbers, but its joint marginal of more than two keys costs pairwise Bayes-tree
    joints: 85 ms per keyframe block on a 10-minute drive, 5 s for the 60 output epochs."""

    def __init__(self, lay: Layout, cpp: Any, info: IntervalInfo) -> None:
        from scipy.sparse.linalg import splu

        # the solve's freed C++ factors and numpy buffers go back to the OS first: left in
        # the heap they stayed resident under H and the LU
        trim_heap()
        h = _information_matrix(lay, cpp, info)  # its temporaries are gone before the LU
        trim_heap()
        self.lay = lay
        # H is symmetric positive definite: no pivoting (partial pivoting filled L and U to
        # 2.3e7 entries on a 10-minute drive instead of 5e5, 1.4 s instead of 0.03 s)
        self.lu = splu(h, permc_spec="COLAMD", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})

    def joint(self, keys: list[int]) -> FloatArray:
        cols = self.lay.cols_of(keys)
        e = np.zeros((self.lay.n_cols, cols.size))
        e[cols, np.arange(cols.size)] = 1.0
        x = self.lu.solve(e)[cols]
        return 0.5 * (x + x.T)

    def solve(self, u: dict[int, FloatArray], out: list[int]) -> dict[int, FloatArray]:
        return self.lay.solve_by_key(self.lu.solve, u, out)


def _information_matrix(lay: Layout, cpp: Any, info: IntervalInfo) -> Any:
    """H = JᵀJ of the C++ rows plus the interval blocks, CSC in our columns. The pieces are
    freed as soon as they are used (on the 1-hour hill-drive GTSAM's sparse Jacobian is 38 MB
    and the CSR Jacobian 24 MB; kept alive under the LU they made the general path's memory
    peak)."""
    from scipy.sparse import coo_matrix, csr_matrix

    sj = cpp.sparseJacobian_()
    pat = sparse_pattern(lay, *jacobian_indices(sj), cache=False)
    vals = sj[2][pat.a_sorted]
    del sj
    rows = np.repeat(np.arange(pat.n_rows), np.diff(pat.indptr))
    a = csr_matrix((vals, (rows, pat.cols_sorted)), shape=(pat.n_rows, lay.n_cols))
    del vals, rows, pat
    h = (a.T @ a).tocsc()
    del a
    c = info.cols
    blk = coo_matrix((info.lam.ravel(), (np.repeat(c, c.shape[1], axis=1).ravel(),
                                         np.tile(c, (1, c.shape[1])).ravel())),
                     shape=(lay.n_cols, lay.n_cols))
    return (h + blk).tocsc()


@cache
def _pieces_plan(blocks: tuple[tuple[int, int], ...], active: tuple[int, ...]
                 ) -> tuple[tuple[tuple[int, ...], tuple[Any, ...]], ...]:
    """``_plan`` of ``hessian_pieces`` (one per block layout): the triples and, per
    constructor argument, the slice of Λ or η it takes (None: a zero block of that shape)."""
    cover = (tuple(active),) if len(active) <= 3 else _cover(len(blocks))
    sl = [slice(a, a + n) for a, n in blocks]
    out = []
    for used, args in _plan(blocks, cover):
        spec = []
        for kind, a, b in args:
            if kind == "G":
                spec.append(("G", sl[a], sl[b]))
            elif kind == "g":
                spec.append(("g", sl[a], None))
            elif kind == "0G":
                spec.append(("0", (blocks[a][1], blocks[b][1]), None))
            else:
                spec.append(("0", (blocks[a][1],), None))
        out.append((used, tuple(spec)))
    return tuple(out)


def hessian_pieces(keys: list[int], lam: FloatArray, eta: FloatArray,
                   active: tuple[int, ...], blocks: tuple[tuple[int, int], ...]) -> list[Any]:
    """Split one group's information (η over ``blocks``: (first column, width) per key) into
    ≤3-key HessianFactors (a pair cover of the blocks, each pair and diagonal block owned by
    one piece: they sum to the whole; used by ``terms``)."""
    hf = gtsam.HessianFactor
    out = []
    for used, spec in _pieces_plan(blocks, tuple(active)):
        a = [lam[x, y] if k == "G" else eta[x] if k == "g" else np.zeros(x) for k, x, y in spec]
        kk = [keys[b] for b in used]
        if len(used) == 3:
            out.append(hf(kk[0], kk[1], kk[2], *a, 0.0))
        elif len(used) == 2:
            out.append(hf(kk[0], kk[1], *a, 0.0))
        else:
            out.append(hf(kk[0], *a, 0.0))
    return out


def information_factor(keys: list[int], lam: FloatArray, eta: FloatArray,
                       blocks: tuple[tuple[int, int], ...], lin: Any) -> Any:
    """A LinearContainerFactor of the information (Λ, η) over ``keys`` (padded ``blocks``),
    linearised at ``lin``: ≤ 3-key Hessian pieces, summed into one factor and converted to
    a Jacobian (iSAM2 runs QR)."""
    # 1e-9 information (σ ≈ 3e4 in any unit) makes the block positive definite so it can be
    # turned into a Jacobian for QR; it is far below any real information.
    lam = lam + 1e-9 * np.eye(lam.shape[0])
    try:
        return _container(keys, lam, eta, blocks, lin)
    except RuntimeError:
        # GTSAM's Cholesky refused the block: indefinite by rounding (a block with entries
        # of 1e15 at a far linearisation point has eigenvalues of ±0.1 from rounding alone,
        # where the 1e-9 above is below the last digit). Its eigenvalues are floored at the
        # rounding level of the block, 10·n·ε·max|λ| (a PSD block, the information a
        # least-squares term can carry), and it is tried once more.
        if not np.all(np.isfinite(lam)):
            raise RuntimeError(f"graph: an information block over {len(keys)} variables "
                               "has non-finite entries (the solve diverged)") from None
        w, v = np.linalg.eigh(0.5 * (lam + lam.T))
        floor = max(10.0 * lam.shape[0] * np.finfo(float).eps * float(np.max(np.abs(w))),
                    1e-9)
        try:
            return _container(keys, (v * np.maximum(w, floor)) @ v.T, eta, blocks, lin)
        except RuntimeError as exc:
            raise RuntimeError(f"graph: an information block over {len(keys)} variables is "
                               "not positive definite even with its eigenvalues floored "
                               f"(GTSAM: {first_line(exc)})") from None


def _container(keys: list[int], lam: FloatArray, eta: FloatArray,
               blocks: tuple[tuple[int, int], ...], lin: Any) -> Any:
    gfg = gtsam.GaussianFactorGraph()
    for f in hessian_pieces(keys, lam, eta, tuple(range(len(keys))), blocks):
        gfg.push_back(f)
    return gtsam.LinearContainerFactor(gtsam.JacobianFactor(gtsam.HessianFactor(gfg)), lin)


def first_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message, or its type's name and "with an
    empty message" (GTSAM's C++ exceptions reach Python with a message that starts with a
    newline, or none at all)."""
    for line in str(exc).splitlines():
        if line.strip():
            return line.strip()
    return f"{type(exc).__name__} with an empty message"
