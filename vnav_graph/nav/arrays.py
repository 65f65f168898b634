"""Array copies and a linear solve for the numba kernels, written so that a cold compile
stays short.

numba compiles every assignment of an array to a slice (``out[k] = x``, ``p[:, :] = a @ b``)
together with a shape-mismatch error whose message formats both shapes (string joins,
integer-to-string conversions). That formatting code is compiled once per process and per
pair of dimensions, and linked into every kernel with such an assignment: measured on the
default run with an empty numba cache, about a fifth of the whole compile time (numbers in
``vnav_graph/util/jit.py``). :func:`put` makes the same copy element by element, with a constant
message. The kernels use it for every array-valued slice assignment; filling with a scalar
(``a[:] = 0.0``) has no shape check and stays as it is.

numba's ``np.linalg.solve`` brings the same message again (its LAPACK wrapper copies with
slice assignments) and wrappers of its own; :func:`solve` is plain Gaussian elimination with
partial pivoting (the algorithm of LAPACK's ``getrf``/``getrs``) for the filters' small
systems (≤ 21 unknowns). :func:`outer` replaces ``np.outer``. :func:`nearest_index` (plain
numpy, not a kernel) finds the nearest of sorted time stamps.
``tests/integration/test_kernel_compile.py`` checks that no kernel of the default run lowers
an array-to-slice assignment.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def put(dst, src):
    """``dst[...] = src`` for 1-D or 2-D arrays of the same shape (views allowed)."""
    if dst.ndim == 1:
        if src.shape[0] != dst.shape[0]:
            raise ValueError("put: source and destination shapes differ")
        for i in range(dst.shape[0]):
            dst[i] = src[i]
    else:
        if src.shape[0] != dst.shape[0] or src.shape[1] != dst.shape[1]:
            raise ValueError("put: source and destination shapes differ")
        for i in range(dst.shape[0]):
            for j in range(dst.shape[1]):
                dst[i, j] = src[i, j]


@njit(cache=True)
def solve(a, b):
    """x with ``a x = b``: a (n, n), b (n,) or (n, m); Gaussian elimination with partial
    pivoting (agrees with ``np.linalg.solve`` to rounding). Raises ``LinAlgError`` when a
    pivot is exactly zero."""
    n = a.shape[0]
    lu = a.copy()
    x = b.copy()
    for c in range(n):
        piv = c
        best = abs(lu[c, c])
        for r in range(c + 1, n):
            if abs(lu[r, c]) > best:
                best = abs(lu[r, c])
                piv = r
        if best == 0.0:
            raise np.linalg.LinAlgError("solve: singular matrix")
        if piv != c:
            for j in range(n):
                tmp = lu[c, j]
                lu[c, j] = lu[piv, j]
                lu[piv, j] = tmp
            if b.ndim == 1:
                tmp = x[c]
                x[c] = x[piv]
                x[piv] = tmp
            else:
                for j in range(x.shape[1]):
                    tmp = x[c, j]
                    x[c, j] = x[piv, j]
                    x[piv, j] = tmp
        for r in range(c + 1, n):
            f = lu[r, c] / lu[c, c]
            if f == 0.0:
                continue
            for j in range(c + 1, n):
                lu[r, j] -= f * lu[c, j]
            if b.ndim == 1:
                x[r] -= f * x[c]
            else:
                for j in range(x.shape[1]):
                    x[r, j] -= f * x[c, j]
    for c in range(n - 1, -1, -1):
        if b.ndim == 1:
            acc = x[c]
            for j in range(c + 1, n):
                acc -= lu[c, j] * x[j]
            x[c] = acc / lu[c, c]
        else:
            for m in range(x.shape[1]):
                acc = x[c, m]
                for j in range(c + 1, n):
                    acc -= lu[c, j] * x[j, m]
                x[c, m] = acc / lu[c, c]
    return x


@njit(cache=True)
def outer(a, b):
    """``np.outer(a, b)`` for 1-D a, b (the same products; numba's own compiles ~3 s)."""
    out = np.empty((a.shape[0], b.shape[0]))
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            out[i, j] = a[i] * b[j]
    return out


def nearest_index(t_ref: np.ndarray, t_q: np.ndarray) -> np.ndarray:
    """Index of the nearest stamp of ``t_ref`` (sorted, at least one) to each of ``t_q``;
    on a tie the later stamp."""
    n = t_ref.size
    if n == 1:
        return np.zeros(np.shape(t_q), dtype=np.intp)
    j = np.clip(np.searchsorted(t_ref, t_q), 1, n - 1)
    return np.where(np.abs(t_ref[j - 1] - t_q) < np.abs(t_ref[j] - t_q), j - 1, j)
