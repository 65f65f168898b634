"""Every estimator's covariance in the one ``ERROR_STATE`` layout of ``Estimate.cov``.

An estimator's own state (a vertical filter's 4 to 8 states, the graph's keyframe variables,
the EKF's 25 states) maps linearly onto the 18 error-state components: ``e = T x`` with
``T`` (18, n). :func:`selection` builds ``T`` from named components and signs (the sign says
whether the estimator's state is "estimated − true", the ``ERROR_STATE`` convention, or its
negative); :func:`embed_error_state` returns ``T P Tᵀ`` for one covariance or a stack of
them, with the components ``T`` does not reach set to NaN (not estimated, as
``Estimate.to_dataframe`` reads them); :func:`mark_absent` does the same for components an
estimator has in its layout but not on this drive (the baro states without a barometer).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..types import ERROR_STATE, ERROR_STATE_DIM
from ..types.streams import FloatArray


def component(name: str, axis: int = 0) -> int:
    """Row of ``ERROR_STATE`` component ``name`` (e.g. ``"pos_n"``, axis 2 = down)."""
    sl = ERROR_STATE[name]
    if not 0 <= axis < sl.stop - sl.start:
        raise ValueError(f"{name} has {sl.stop - sl.start} axes, not axis {axis}")
    return sl.start + axis


def selection(entries: Iterable[tuple[str, int, int, float]], n: int) -> FloatArray:
    """``T`` (18, n) with ``T[component(name, axis), col] = sign`` for each entry
    ``(name, axis, col, sign)``."""
    tmat = np.zeros((ERROR_STATE_DIM, n))
    for name, axis, col, sign in entries:
        tmat[component(name, axis), col] = sign
    return tmat


def embed_error_state(cov: FloatArray, tmat: FloatArray) -> FloatArray:
    """``T P Tᵀ`` of a covariance (n, n) or a stack (M, n, n); rows and columns of the
    components ``T`` does not reach (all-zero rows) are NaN."""
    if cov.ndim == 2:
        out = tmat @ cov @ tmat.T
    else:
        out = np.einsum("ij,mjk,lk->mil", tmat, cov, tmat)
    absent = ~np.any(tmat != 0.0, axis=1)
    if absent.any():
        out[..., absent, :] = np.nan
        out[..., :, absent] = np.nan
    return out


def mark_absent(cov: FloatArray, names: Iterable[str]) -> FloatArray:
    """Set the rows and columns of the named components to NaN (in place; returned)."""
    for name in names:
        sl = ERROR_STATE[name]
        cov[..., sl, :] = np.nan
        cov[..., :, sl] = np.nan
    return cov


BARO_COMPONENTS = ("baro_scale", "baro_latency", "baro_bias")
