"""Banded-arrow linear algebra of the batch factor-graph smoother (numpy / scipy / numba).

The Gauss-Newton normal equations of ``graph-batch`` have an *arrow* structure when the
variables are ordered keyframe by keyframe: every factor couples at most two consecutive
keyframes (IMU preintegration, Gauss-Markov baro-bias link, interval baro/GNSS terms), so the
keyframe part ``A`` is banded with half-bandwidth ``w = 2·bs − 1`` (``bs`` = variables per
keyframe), and a few global variables (baro scale and latency) couple to everything::

    H = [[A,   B],      A: (n, n) banded, B: (n, m) dense, D: (m, m), m = 2 (or 0)
         [Bᵀ,  D]]

Solve (Schur complement on the m global columns; Golub & Van Loan 4th ed. §4.3 for the banded
Cholesky): W = A⁻¹[g_x, B], S = D − BᵀA⁻¹B, δ_g = S⁻¹(g_g − BᵀA⁻¹g_x), δ_x = A⁻¹g_x − A⁻¹B δ_g.
Cost O(n·w²) per factorisation.

Covariance: H⁻¹ = [[A⁻¹ + W_B S⁻¹ W_Bᵀ, −W_B S⁻¹], [−S⁻¹W_Bᵀ, S⁻¹]] with W_B = A⁻¹B; the
entries of A⁻¹ inside the band come from the Takahashi selected-inversion recursion on the
banded Cholesky factor L (Takahashi, Fagan & Chin 1973; Rue & Held 2005 §2.4):
Σ_ij = δ_ij/L_ii² − (1/L_ii)·Σ_{k=i+1}^{i+w} L_ki Σ_kj, for j ≥ i, run from i = n−1 down —
O(n·w²), no dense inverse.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

from ....types.streams import FloatArray
from ....util.pages import small_pages


@dataclass
class ArrowFactor:
    """Factorised arrow system: banded Cholesky ``cb`` of A (lower, scipy band storage
    cb[d, j] = L[j+d, j]), W_B = A⁻¹B (n, m), S⁻¹ (m, m), n keyframe columns."""

    cb: FloatArray
    wb: FloatArray
    s_inv: FloatArray
    n: int

    def solve(self, g: FloatArray) -> FloatArray:
        """H⁻¹ g for a right-hand side g (n + m,)."""
        n = self.n
        y = cho_solve_banded((self.cb, True), g[:n])
        if self.wb.shape[1] == 0:
            return y
        dg = self.s_inv @ (g[n:] - self.wb.T @ g[:n])
        return np.concatenate([y - self.wb @ dg, dg])

    def band_inverse(self) -> FloatArray:
        """Band of A⁻¹ (same storage as ``cb``): sb[d, j] = (A⁻¹)[j+d, j]."""
        return _takahashi(self.cb)

    def cov_block(self, sb: FloatArray, cols: np.ndarray) -> FloatArray:
        """Covariance (H⁻¹) of the keyframe columns ``cols`` (all within one band width of each
        other) followed by all m global columns, from the selected inverse ``sb``."""
        c = np.asarray(cols)
        i, j = np.meshgrid(c, c, indexing="ij")
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        d = hi - lo
        if np.any(d >= sb.shape[0]):
            raise ValueError("cov_block: columns farther apart than the band")
        a_inv = sb[d, lo]
        m = self.wb.shape[1]
        out = np.zeros((c.size + m, c.size + m))
        wb = self.wb[c]
        out[:c.size, :c.size] = a_inv + wb @ self.s_inv @ wb.T
        if m:
            out[:c.size, c.size:] = -wb @ self.s_inv
            out[c.size:, :c.size] = out[:c.size, c.size:].T
            out[c.size:, c.size:] = self.s_inv
        return out


@njit(cache=True)
def _takahashi(cb):
    w1, n = cb.shape
    w = w1 - 1
    sb = np.zeros((w1, n))
    for i in range(n - 1, -1, -1):
        lii = cb[0, i]
        top = min(i + w, n - 1)
        for j in range(top, i - 1, -1):
            s = 0.0
            for k in range(i + 1, top + 1):
                lki = cb[k - i, i]
                if lki == 0.0:
                    continue
                if k >= j:
                    skj = sb[k - j, j]
                else:
                    skj = sb[j - k, k]
                s += lki * skj
            val = -s / lii
            if j == i:
                val += 1.0 / (lii * lii)
            sb[j - i, i] = val
    return sb


@njit(cache=True)
def _accumulate(indptr, cols, vals, rhs, nb, w, ab, bm, dm, g):
    for r in range(indptr.size - 1):
        lo, hi = indptr[r], indptr[r + 1]
        br = rhs[r]
        for p in range(lo, hi):
            ci = cols[p]
            vi = vals[p]
            if vi == 0.0:
                continue
            g[ci] += vi * br
            for q in range(lo, hi):
                cj = cols[q]
                if cj > ci:
                    continue
                vj = vals[q]
                if vj == 0.0:
                    continue
                if ci < nb:
                    d = ci - cj
                    if d > w:
                        return False
                    ab[d, cj] += vi * vj
                elif cj < nb:
                    bm[cj, ci - nb] += vi * vj
                else:
                    dm[ci - nb, cj - nb] += vi * vj
                    if ci != cj:
                        dm[cj - nb, ci - nb] += vi * vj
    return True


@njit(cache=True)
def _accumulate_blocks(bcols, lam, eta, nb, w, ab, bm, dm, g):
    for gi in range(bcols.shape[0]):
        c = bcols[gi]
        for a in range(c.size):
            ci = c[a]
            g[ci] += eta[gi, a]
            for b in range(c.size):
                cj = c[b]
                if cj > ci:
                    continue
                v = lam[gi, a, b]
                if ci < nb:
                    d = ci - cj
                    if d > w:
                        return False
                    ab[d, cj] += v
                elif cj < nb:
                    bm[cj, ci - nb] += v
                else:
                    dm[ci - nb, cj - nb] += v
                    if ci != cj:
                        dm[cj - nb, ci - nb] += v
    return True


def assemble(
    n_cols: int, n_band: int, bandwidth: int,
    indptr: np.ndarray, cols: np.ndarray, vals: FloatArray, rhs: FloatArray,
    blk_cols: np.ndarray | None = None, blk_lam: FloatArray | None = None,
    blk_eta: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Normal equations H = AᵀA, g = Aᵀb of the whitened least-squares rows ‖A δ − b‖² in
    arrow form, accumulated row by row (numba; no sparse matrix product).

    Parameters
    ----------
    n_cols : total number of columns (n_band keyframe columns, then the global ones)
    bandwidth : half-bandwidth w of the keyframe part
    indptr (rows+1,), cols (nnz,), vals (nnz,) : CSR rows of A in our column order
    rhs : (rows,) right-hand side b (A δ ≈ b)
    blk_cols (G, c), blk_lam (G, c, c), blk_eta (G, c) : optional information blocks
        (Λ = JᵀJ, η = −Jᵀr of already reduced rows) added to H and g

    Returns (ab (w+1, n_band) lower band of A, B (n_band, m), D (m, m), g (n_cols,)).
    """
    m = n_cols - n_band
    ab = np.zeros((bandwidth + 1, n_band))
    bm = np.zeros((n_band, m))
    dm = np.zeros((m, m))
    g = np.zeros(n_cols)
    ok = _accumulate(np.ascontiguousarray(indptr, np.int64), np.ascontiguousarray(cols, np.int64),
                     np.ascontiguousarray(vals, np.float64), np.ascontiguousarray(rhs, np.float64),
                     n_band, bandwidth, ab, bm, dm, g)
    if ok and blk_cols is not None and blk_lam is not None and blk_eta is not None:
        ok = _accumulate_blocks(np.ascontiguousarray(blk_cols, np.int64),
                                np.ascontiguousarray(blk_lam), np.ascontiguousarray(blk_eta),
                                n_band, bandwidth, ab, bm, dm, g)
    if not ok:
        raise ValueError("assemble: an entry lies outside the keyframe band")
    return ab, bm, dm, g


def factorize(ab: FloatArray, bmat: FloatArray, dmat: FloatArray) -> ArrowFactor:
    """Cholesky of the arrow system; raises ``LinAlgError`` when H is not positive definite."""
    cb = cholesky_banded(ab, lower=True)
    n = ab.shape[1]
    if bmat.shape[1] == 0:
        return ArrowFactor(cb, np.zeros((n, 0)), np.zeros((0, 0)), n)
    wb = cho_solve_banded((cb, True), bmat)
    s = dmat - bmat.T @ wb
    s = 0.5 * (s + s.T)
    try:
        np.linalg.cholesky(s)
    except np.linalg.LinAlgError as exc:
        raise LinAlgError("Schur complement of the global variables is not positive "
                          "definite") from exc
    return ArrowFactor(cb, wb, np.linalg.inv(s), n)


def single_thread_blas() -> Any:
    """Context limiting BLAS to one thread. The solver's BLAS work is many small batched
    products and one banded Cholesky; with OpenBLAS's default two threads on this 2-core
    machine, one busy core made the 10-minute batch solve 0.27 → 0.34 s (ratio to the
    single-threaded C++ floor 2.0 → 2.5), single-threaded it stayed at 0.28 s; idle, both
    take the same time (``docs/graph.md``)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


@contextmanager
def solver_context() -> Iterator[None]:
    """The graph solvers' run context: BLAS on one thread (``single_thread_blas``) and numpy
    on small pages (``small_pages``)."""
    with single_thread_blas(), small_pages():
        yield


_MALLOC_TRIM: Any = None  # glibc's malloc_trim, False where there is none


def trim_heap() -> None:
    """Give the C heap's free pages back to the operating system (glibc ``malloc_trim(0)``;
    a no-op elsewhere). Freed small C++ objects (GTSAM's) stay resident otherwise: releasing
    graph-isam2's Bayes tree before its final batch pass left RSS at 671 MB on a 1-hour drive,
    trimmed 446 MB, and the pass's peak fell 866 → 700 MB (``docs/graph_performance.md``)."""
    global _MALLOC_TRIM
    if _MALLOC_TRIM is None:
        import ctypes

        try:
            _MALLOC_TRIM = ctypes.CDLL(None).malloc_trim
            _MALLOC_TRIM.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _MALLOC_TRIM = False
    if _MALLOC_TRIM:
        _MALLOC_TRIM(0)
