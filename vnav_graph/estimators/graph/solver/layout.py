"""Column layout of the batch normal equations, derived from the keys of the linearised graph,
and the banded-arrow fast path (``linalg``) that runs when the structure fits it.

The variables of the linearised C++ graph (``GaussianFactorGraph.keys()``, sorted, which is
also the column order of ``sparseJacobian_``) are split into

- the keyframe *template*: X(k) Pose3 (6), V(k) velocity (3), B(k) IMU bias (6, accel then
  gyro), C(k) baro bias (1, with a barometer), G(k) GNSS Gauss-Markov error (d = 1, 2 or 3,
  when ``GraphConfig.gnss_gm_sd_h`` or ``gnss_gm_sd_v`` > 0) for k = 0 … K−1, ordered
  keyframe by keyframe: keyframe k owns columns k·bs + [0, bs) (bs = 15 + 1 with baro + d);
- the *global* variables: every other key — K(0) = (s, τd) first, then any variable a user
  added, in key order — in columns n_band = K·bs onwards.

The arrow form (banded keyframe block + dense global border, ``linalg``) holds the system when
every factor couples keyframes at most one apart (half-bandwidth 2·bs − 1) and the global part
has at most ``MAX_GLOBAL_DIM`` columns. ``Layout.fits_band`` says whether the structure of
the graph last linearised does; otherwise (a factor linking keyframes ≥ 2 apart, many extra
variables) ``general`` solves the same system by GTSAM's sparse elimination.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....types.streams import FloatArray
from ..model import interval_factors as gf
from . import linalg as gla

MAX_GLOBAL_DIM = 64  # global columns kept as the dense border of the arrow


@dataclass
class Layout:
    """Our column of every variable (``key_cols[key] = (first column, dim)``); ``g2m`` maps
    GTSAM's sparse-Jacobian columns (keys in sorted order) to ours; ``globals_`` lists the
    global keys in column order (K(0) first when the drive has a barometer)."""

    nk: int
    bs: int
    has_baro: bool
    n_band: int
    n_cols: int
    g2m: np.ndarray
    keys: list[int]
    key_cols: dict[int, tuple[int, int]]
    globals_: list[int]
    pattern: Any = None  # SparsePattern of the graph last linearised with this layout
    banded: bool | None = None  # path of the solver, decided at the first linearisation
    ordering: Any = None  # elimination ordering of the general path, computed once
    gm_dim: int = 0  # dimension of G(k), the GNSS Gauss-Markov error, in the template

    @property
    def has_gm(self) -> bool:
        return self.gm_dim > 0

    @property
    def gm_col(self) -> int:
        """First column of G(k) inside keyframe k's block: its last d (``template_keys``)."""
        return self.bs - self.gm_dim

    @property
    def bandwidth(self) -> int:
        return 2 * self.bs - 1

    @property
    def extra_keys(self) -> list[int]:
        """Variables outside the keyframe template, the baro calibration K(0) and the
        accelerometer scale factors A(0) (reported as ``info["accel_scale"]``)."""
        return [k for k in self.globals_ if k not in (K(0), A(0))]

    @property
    def term_cols(self) -> np.ndarray:
        """Interval-term columns (``factors`` order) present in this layout."""
        core = np.arange(gf.N_CORE if self.has_baro else 12)
        gm = np.arange(gf.N_COLS, gf.n_cols_of(self.gm_dim))
        return np.r_[core, np.arange(gf.N_CORE, gf.N_COLS), gm]

    def block_cols(self, k: np.ndarray) -> np.ndarray:
        """Our columns of the interval-term blocks (X_k, X_k+1, [C_k, C_k+1, K,] accel bias
        of B_k, [G_k, G_k+1]), in the order of ``term_cols`` (G, 19|15 [+2d])."""
        k = np.asarray(k)[:, None]
        six = np.arange(6)[None, :]
        parts = [k * self.bs + six, (k + 1) * self.bs + six]
        if self.has_baro:
            kc = self.key_cols[K(0)][0]
            parts += [k * self.bs + 15, (k + 1) * self.bs + 15,
                      np.full_like(k, kc), np.full_like(k, kc + 1)]
        parts.append(k * self.bs + 9 + np.arange(3)[None, :])
        if self.has_gm:
            g = self.gm_col + np.arange(self.gm_dim)[None, :]
            parts += [k * self.bs + g, (k + 1) * self.bs + g]
        return np.concatenate(parts, axis=1)

    def cols_of(self, keys: list[int]) -> np.ndarray:
        return np.concatenate([c + np.arange(d) for c, d in (self.key_cols[k] for k in keys)])

    def vector_values(self, delta: FloatArray) -> Any:
        """``gtsam.VectorValues`` of a step in our column order."""
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
            if self.has_gm:
                ins(G(k), row[self.gm_col:self.bs])
        for key in self.globals_:
            c, n = self.key_cols[key]
            ins(key, delta[c:c + n])
        return vv

    def solve_by_key(self, solve: Any, u: dict[int, FloatArray],
                     out: list[int]) -> dict[int, FloatArray]:
        """``solve`` (a column-vector solve, H⁻¹·) of u given per key (absent keys: 0),
        returned for the keys ``out`` (shared by the banded and the general factorisation)."""
        vec = np.zeros(self.n_cols)
        for key, val in u.items():
            c, n = self.key_cols[key]
            vec[c:c + n] = val
        x = solve(vec)
        return {key: x[self.key_cols[key][0]:sum(self.key_cols[key])] for key in out}

    def fits_band(self) -> bool:
        """Whether the graph last linearised fits the arrow form (see the module docstring)."""
        return (self.n_cols - self.n_band <= MAX_GLOBAL_DIM and self.pattern is not None
                and self.pattern.band_ok)


def template_keys(nk: int, has_baro: bool, gm_dim: int = 0
                  ) -> list[tuple[int, int, int]]:
    """(key, dim, column) of the keyframe template (``gm_dim``: dimension of G(k), 0: none)."""
    bs = 15 + int(has_baro) + gm_dim
    items = []
    for k in range(nk):
        o = k * bs
        items += [(X(k), 6, o), (V(k), 3, o + 6), (B(k), 6, o + 9)]
        if has_baro:
            items.append((C(k), 1, o + 15))
        if gm_dim:
            items.append((G(k), gm_dim, o + bs - gm_dim))
    return items


def make_layout(nk: int, has_baro: bool, graph_keys: Any, dims: dict[int, int],
                gm_dim: int = 0) -> Layout:
    """Layout of a graph with the variables ``graph_keys`` (``dims``: tangent dimension of
    every key, from ``Values.dims()``); ``gm_dim``: dimension of G(k) in the template (0:
    none). Raises ``RuntimeError`` naming a missing template variable."""
    keys = sorted(int(k) for k in graph_keys)
    bs = 15 + int(has_baro) + gm_dim
    n_band = nk * bs
    items = template_keys(nk, has_baro, gm_dim)
    have = set(keys)
    for key, _, _ in items:
        if key not in have:
            raise RuntimeError(f"graph: the linearised graph has no factor on "
                               f"{gtsam.DefaultKeyFormatter(key)} (a keyframe variable)")
    tmpl = {it[0] for it in items}
    glob = [k for k in keys if k not in tmpl]
    if has_baro:
        if K(0) not in have:
            raise RuntimeError("graph: the linearised graph has no factor on k0 (baro "
                               "calibration)")
        glob = [K(0)] + [k for k in glob if k != K(0)]
    col = n_band
    for key in glob:
        items.append((key, int(dims[key]), col))
        col += int(dims[key])
    key_cols = {key: (off, dim) for key, dim, off in items}
    g2m = np.concatenate([key_cols[k][0] + np.arange(key_cols[k][1]) for k in keys])
    return Layout(nk, bs, has_baro, n_band, col, g2m, keys, key_cols, glob, gm_dim=gm_dim)


@dataclass
class SparsePattern:
    """Row/column bookkeeping of GTSAM's sparse Jacobian of one graph: the pattern (entry
    order included) is the same at every linearisation point, so it is computed once.
    ``band_ok``: every row's keyframe columns lie within the half-bandwidth."""

    i: np.ndarray
    j: np.ndarray
    rhs_entries: np.ndarray  # entries of the right-hand-side column
    rhs_rows: np.ndarray
    a_sorted: np.ndarray  # matrix entries, ordered by row
    cols_sorted: np.ndarray  # their columns in our layout
    indptr: np.ndarray
    n_rows: int
    band_ok: bool


def _band_ok(lay: Layout, cols: np.ndarray, indptr: np.ndarray) -> bool:
    """Largest distance between two keyframe-band columns of one row ≤ the bandwidth."""
    if cols.size == 0:
        return True
    band = cols < lay.n_band
    lo = np.where(band, cols, np.iinfo(cols.dtype).max)
    hi = np.where(band, cols, -1)
    starts = indptr[:-1][np.diff(indptr) > 0]
    rmin = np.minimum.reduceat(lo, starts)
    rmax = np.maximum.reduceat(hi, starts)
    has = rmax >= 0
    return bool(np.all(rmax[has] - rmin[has] <= lay.bandwidth))


def jacobian_indices(sj: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """Zero-based row and column indices (int32) of GTSAM's ``sparseJacobian_()`` triplets
    (3, nnz), which holds them 1-based, as doubles."""
    i = sj[0].astype(np.int32)
    i -= 1
    j = sj[1].astype(np.int32)
    j -= 1
    return i, j


def sparse_pattern(lay: Layout, i: np.ndarray, j: np.ndarray,
                   cache: bool = True) -> SparsePattern:
    """The pattern of GTSAM's sparse Jacobian (i, j); kept in ``lay.pattern`` (the banded
    path reuses it at every linearisation) unless ``cache`` is False (the general path
    needs it only once per factorisation: ~50 MB on a 1-hour drive)."""
    pat = lay.pattern
    if pat is not None and np.array_equal(pat.i, i) and np.array_equal(pat.j, j):
        return pat
    if int(j.max()) != lay.n_cols:
        raise RuntimeError("graph: the linearised graph's variables changed during the solve")
    is_b = j == lay.n_cols
    nrow = int(i.max()) + 1
    a = np.flatnonzero(~is_b)
    order = np.argsort(i[a], kind="stable")
    # entry and column indices as int32 (the Jacobian has < 2³¹ entries and columns): the
    # cached pattern is ~13 MB smaller on a 1-hour drive, and it is alive under the peak
    a = a[order].astype(np.int32)
    cols = lay.g2m[j[a]].astype(np.int32)
    indptr = np.r_[0, np.cumsum(np.bincount(i[a], minlength=nrow))]
    pat = SparsePattern(i, j, np.flatnonzero(is_b), i[is_b], a, cols, indptr, nrow,
                        _band_ok(lay, cols, indptr))
    if cache:
        lay.pattern = pat
    return pat


def linearize(lay: Layout, graph: Any, vals: Any) -> tuple[Any, SparsePattern, FloatArray]:
    """Linearised C++ graph, its sparse pattern and the entries of its sparse Jacobian."""
    gfg = graph.linearize(vals)
    sj = gfg.sparseJacobian_()
    pat = sparse_pattern(lay, *jacobian_indices(sj))
    return gfg, pat, sj[2]


@dataclass(frozen=True)
class IntervalInfo:
    """Per-interval information of the interval rows: intervals ``groups`` (G,), our
    columns ``cols`` (G, c), Λ (G, c, c) and η (G, c) in ``Layout.term_cols`` order."""

    groups: np.ndarray
    cols: np.ndarray
    lam: FloatArray
    eta: FloatArray


def interval_info(lay: Layout, rows: gf.IntervalRows) -> IntervalInfo:
    assert rows.jac.shape[0] == rows.r.size, "interval rows without their Jacobian"
    groups, lam, eta, _ = gf.group_information(rows)
    tc = lay.term_cols
    return IntervalInfo(groups, lay.block_cols(groups), lam[:, tc[:, None], tc[None, :]],
                        eta[:, tc])


def hessian_diagonal(lay: Layout, pat: SparsePattern, v: FloatArray, info: IntervalInfo
                     ) -> FloatArray:
    """diag(H) of the C++ rows plus the interval blocks, in our columns."""
    d = np.bincount(pat.cols_sorted, weights=v[pat.a_sorted] ** 2, minlength=lay.n_cols)
    np.add.at(d, info.cols.ravel(), np.diagonal(info.lam, axis1=1, axis2=2).ravel())
    return d


@dataclass
class BandedSystem:
    """Normal equations H δ = g in arrow form (``linalg.assemble``) and, once solved, their
    factorisation (kept for the covariance)."""

    lay: Layout
    ab: FloatArray
    bm: FloatArray
    dm: FloatArray
    g: FloatArray
    fac: gla.ArrowFactor | None = None
    # largest Marquardt damping μ (of μ·diag(H)) a singular system needed in ``step`` or
    # ``covariance`` (0: none); reported as a fallback, and a covariance from a damped
    # factorisation understates σ
    damping: float = 0.0

    @classmethod
    def build(cls, lay: Layout, pat: SparsePattern, v: FloatArray, info: IntervalInfo
              ) -> BandedSystem:
        b = np.zeros(pat.n_rows)
        b[pat.rhs_rows] = v[pat.rhs_entries]
        ab, bm, dm, g = gla.assemble(lay.n_cols, lay.n_band, lay.bandwidth, pat.indptr,
                                     pat.cols_sorted, v[pat.a_sorted], b, info.cols, info.lam,
                                     info.eta)
        return cls(lay, ab, bm, dm, g)

    def step(self) -> tuple[Any, float]:
        """Gauss-Newton step (as VectorValues) and the cost decrease ½ δᵀg it predicts."""
        self.fac, mu = factorize(self.ab, self.bm, self.dm)
        self.damping = max(self.damping, mu)
        delta = self.fac.solve(self.g)
        return self.lay.vector_values(delta), 0.5 * float(delta @ self.g)

    def release_factor(self) -> None:
        """Free the factorisation (``covariance`` factorises again if it is needed)."""
        self.fac = None

    def damped(self, mu: float) -> Any:
        """Step of H + μ·diag(H) (Levenberg-Marquardt damping)."""
        ab2 = self.ab.copy()
        ab2[0] *= 1.0 + mu
        fac, _ = factorize(ab2, self.bm, self.dm + mu * np.diag(np.diag(self.dm)))
        return self.lay.vector_values(fac.solve(self.g))

    def covariance(self) -> BandedCovariance:
        if self.fac is None:
            self.fac, mu = factorize(self.ab, self.bm, self.dm)
            self.damping = max(self.damping, mu)
        return BandedCovariance(self.lay, self.fac)


class BandedCovariance:
    """Selected entries of H⁻¹ from the arrow factorisation (Takahashi band inverse)."""

    def __init__(self, lay: Layout, fac: gla.ArrowFactor) -> None:
        self.lay, self.fac = lay, fac
        self._sb: FloatArray | None = None

    def joint(self, keys: list[int]) -> FloatArray:
        """Joint covariance of ``keys`` (in that order; keyframe keys within one band width)."""
        lay = self.lay
        cols = lay.cols_of(keys)
        band = cols < lay.n_band
        if self._sb is None:
            self._sb = self.fac.band_inverse()
        full = self.fac.cov_block(self._sb, cols[band])
        pos = np.where(band, np.cumsum(band) - 1, int(band.sum()) + cols - lay.n_band)
        return full[np.ix_(pos, pos)]

    def solve(self, u: dict[int, FloatArray], out: list[int]) -> dict[int, FloatArray]:
        """H⁻¹u for u given per key (absent keys: 0), returned for the keys ``out``."""
        return self.lay.solve_by_key(self.fac.solve, u, out)


def factorize(ab: FloatArray, bm: FloatArray, dm: FloatArray
              ) -> tuple[gla.ArrowFactor, float]:
    """Cholesky of the normal equations and the damping it needed: if H is numerically
    singular (e.g. 1 Hz averaged IMU with an unobservable direction), retry with growing
    Marquardt damping μ·diag(H) (μ returned; 0 when none was needed)."""
    mu = 0.0
    for _ in range(6):
        try:
            if mu == 0.0:
                return gla.factorize(ab, bm, dm), 0.0
            ab2 = ab.copy()
            ab2[0] += mu * ab[0] + 1e-12
            return gla.factorize(ab2, bm, dm + np.diag(mu * np.diag(dm) + 1e-12)), mu
        except gla.LinAlgError:
            mu = 1e-9 if mu == 0.0 else mu * 100.0
    raise RuntimeError(
        "graph: the Gauss-Newton system stays singular even with Marquardt damping 1e-1·diag(H) "
        "— the drive does not determine the states (check IMU rate/units and GNSS coverage)")
