"""Rauch-Tung-Striebel smoothing of the forward EKF pass (``ekf-rts``).

``rts_smooth`` runs backward over the covariance grid with the transition matrices and
process noise the forward kernel stored (``ekf.model`` docstring); ``smooth_corrections``
carries the smoothed errors to every output epoch and ``apply_error`` removes them from the
nominal states.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial.transform import Rotation

from ...geo.earth import radii
from ...nav.arrays import outer, put, solve
from ...types import FloatArray
from .model import (
    IBA,
    IBB,
    IBG,
    IGH,
    IKA,
    IMB,
    ISC,
    ITD,
    NING,
    NPACK,
    NX,
    PBA,
    PBB,
    PBG,
    PGH,
    PKA,
    PMB,
    PSC,
    PTD,
    pack,
    reset_jacobian,
    step_phi,
    unpack,
)


@njit(cache=True)
def rts_smooth(rts_p, rts_ing, rts_q, corr, reset_at, tau_g, tau_a, tau_b, tau_h, cov_out_of,
               n_cov_out):
    """Backward RTS pass on the covariance grid (module docstring).

    Returns ê^s (K, NX) — the smoothed estimate of the error of the filtered (post-update)
    nominal state at each grid epoch, estimated minus true — and the packed smoothed
    covariances at the covariance-output epochs.
    """
    kk = rts_p.shape[0]
    es = np.zeros((kk, NX))
    cov_s = np.empty((n_cov_out, NPACK))
    ps = unpack(rts_p[kk - 1])
    if cov_out_of[kk - 1] >= 0:
        pack(ps, cov_s[cov_out_of[kk - 1]])
    for k in range(kk - 2, -1, -1):
        pk = unpack(rts_p[k])
        ing = rts_ing[k + 1]
        phi = step_phi(ing, tau_g, tau_a, tau_b, tau_h)
        if not np.isnan(reset_at[k + 1]):
            phi = reset_jacobian(reset_at[k + 1]) @ phi
        pm = phi @ pk @ phi.T
        for a in range(NX):
            pm[a, a] += rts_q[k + 1, a]
        # G = P⁺ Φᵀ (P⁻)⁻¹ through the correlation matrix (scales differ by ~1e12); a state
        # switched off (zero variance: the GNSS height error state by default) keeps G's
        # row and column zero
        dgm = np.diag(pm)
        dinv = np.zeros(NX)
        for a in range(NX):
            if dgm[a] > 0.0:
                dinv[a] = 1.0 / np.sqrt(dgm[a])
        corr_m = pm * outer(dinv, dinv)
        for a in range(NX):
            if dgm[a] <= 0.0:
                corr_m[a, a] = 1.0
        rhs = (phi @ pk) * dinv.reshape(NX, 1)
        gt = solve(corr_m, rhs) * dinv.reshape(NX, 1)
        g = gt.T
        put(es[k], g @ (es[k + 1] + corr[k + 1]))
        ps = pk + g @ (ps - pm) @ g.T
        ps = 0.5 * (ps + ps.T)
        if cov_out_of[k] >= 0:
            pack(ps, cov_s[cov_out_of[k]])
    return es, cov_s


def warm_up() -> None:
    """Compile ``rts_smooth`` for the argument types ``EKFRTS.run`` passes, on a two-epoch
    problem (identity covariances, no process noise, no reset). The first-run prewarm
    (``vnav_graph.jit.WARMUPS``) calls it in whichever process is free first."""
    k = 2
    p = np.zeros((k, NPACK))
    for row in p:
        pack(np.eye(NX), row)
    rts_smooth(p, np.zeros((k, NING)), np.zeros((k, NX)), np.zeros((k, NX)),
               np.full(k, np.nan), 1.0, 1.0, 1.0, 1.0, np.arange(k, dtype=np.int64), k)


def smooth_corrections(grid_t: FloatArray, t_out: FloatArray, corr: FloatArray,
                       reset_at: FloatArray, es: FloatArray) -> FloatArray:
    """Smoothed error estimate at every output epoch (N_out, 21), estimated minus true.

    At a grid epoch it is ê^s_k; inside (t_k, t_{k+1}) it is interpolated linearly between
    ê^s_k (after the update at t_k) and ê^s_{k+1} + c_{k+1} (the same error relative to the
    un-updated nominal state that runs up to t_{k+1}); across a heading reset it is held.
    """
    k = np.searchsorted(grid_t, t_out, side="right") - 1
    k = np.clip(k, 0, grid_t.size - 1)
    at_grid = np.isclose(t_out, grid_t[k], rtol=0, atol=1e-12)
    kn = np.minimum(k + 1, grid_t.size - 1)
    span = np.where(kn > k, grid_t[kn] - grid_t[k], 1.0)
    al = np.where(at_grid, 0.0, (t_out - grid_t[k]) / span)[:, None]
    right = es[kn] + corr[kn]
    right = np.where(np.isnan(reset_at[kn])[:, None], right, es[k])
    return (1.0 - al) * es[k] + al * right


def apply_error(lla: FloatArray, vel: FloatArray, q: FloatArray, par: FloatArray,
                e: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Remove estimated errors e (N, NX) (estimated minus true) from nominal states."""
    rn, re = radii(lla[:, 0])
    lla2 = lla.copy()
    lla2[:, 0] -= e[:, 0] / (rn + lla[:, 2])
    lla2[:, 1] -= e[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0]))
    lla2[:, 2] += e[:, 2]
    vel2 = vel - e[:, 3:6]
    rot = Rotation.from_rotvec(-e[:, 6:9]) * Rotation.from_quat(q, scalar_first=True)
    q2 = rot.as_quat(scalar_first=True)
    par2 = par.copy()
    par2[:, PBG:PBG + 3] -= e[:, IBG:IBG + 3]
    par2[:, PBA:PBA + 3] -= e[:, IBA:IBA + 3]
    par2[:, PKA:PKA + 3] -= e[:, IKA:IKA + 3]
    par2[:, PMB:PMB + 3] -= e[:, IMB:IMB + 3]
    par2[:, PSC] -= e[:, ISC]
    par2[:, PTD] -= e[:, ITD]
    par2[:, PBB] -= e[:, IBB]
    par2[:, PGH] -= e[:, IGH]
    return lla2, vel2, q2, par2
