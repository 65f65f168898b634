"""Rauch-Tung-Striebel smoothing of the forward EKF pass (``ekf-rts``).

``rts_smooth`` runs backward over the covariance grid with the transition matrices and
process noise the forward kernel stored (docs/ekf.md, "RTS smoother"); ``smooth_corrections``
carries the smoothed errors to every output epoch and ``apply_error`` removes them from the
nominal states.

The reported mean baro bias b̄ = Σ_k w_k b_k (``mean_weights``: the output epochs' average,
written on the grid) has the variance Σ_k Σ_m w_k w_m P_{k,m}[b, b], where the smoothed
cross-covariances are P_{k,m} = G_k P_{k+1,m} (m > k; G the smoother gain). ``rts_smooth``
accumulates it backward with u_k = Σ_{m≥k} w_m P_{k,m}[:, b] = w_k P_{k,k}[:, b] + G_k u_{k+1}:
var = Σ_k w_k (2 u_k[b] − w_k P_{k,k}[b, b]). The average of the pointwise σ's is only an
upper bound of it (median 0.31 m against graph-batch's 0.21 m from its joint covariance on
the simulated `default` drives); with the cross-covariances the two agree within 1–2 %
(``tests/integration/test_graph_equivalence.py``; ``docs/real_logs.md``, "Default real-log
baro prior").
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from ...geo.earth import radii
from ...nav.arrays import outer, put, solve
from ...types.streams import FloatArray
from .model import (
    IBA,
    IBB,
    IBG,
    IGE,
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
    PGE,
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
               n_cov_out, w_mean):
    """Backward RTS pass on the covariance grid (module docstring).

    Returns ê^s (K, NX) — the smoothed estimate of the error of the filtered (post-update)
    nominal state at each grid epoch, estimated minus true —, the packed smoothed
    covariances at the covariance-output epochs and the smoothed variance of the weighted
    mean Σ_k w_mean[k]·b_k of the baro bias.
    """
    kk = rts_p.shape[0]
    es = np.zeros((kk, NX))
    cov_s = np.empty((n_cov_out, NPACK))
    ps = unpack(rts_p[kk - 1])
    if cov_out_of[kk - 1] >= 0:
        pack(ps, cov_s[cov_out_of[kk - 1]])
    u = w_mean[kk - 1] * ps[:, IBB]  # Σ_{m≥k} w_m P_{k,m}[:, b] (module docstring)
    var_mean = w_mean[kk - 1] * u[IBB]
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
        u = w_mean[k] * ps[:, IBB] + g @ u
        var_mean += w_mean[k] * (2.0 * u[IBB] - w_mean[k] * ps[IBB, IBB])
    return es, cov_s, var_mean


def warm_up() -> None:
    """Compile ``rts_smooth`` for the argument types ``EKFRTS.run`` passes, on a two-epoch
    problem (identity covariances, no process noise, no reset). The first-run prewarm
    (``vnav_graph.util.jit.WARMUPS``) calls it in whichever process is free first."""
    k = 2
    p = np.zeros((k, NPACK))
    for row in p:
        pack(np.eye(NX), row)
    rts_smooth(p, np.zeros((k, NING)), np.zeros((k, NX)), np.zeros((k, NX)),
               np.full(k, np.nan), 1.0, 1.0, 1.0, 1.0, np.arange(k, dtype=np.int64), k,
               np.full(k, 1.0 / k))


def _interp(grid_t: FloatArray, t_out: FloatArray, reset_at: FloatArray
            ) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """For each output epoch: its grid epoch k, the next one kn and the weight α of kn in
    ``smooth_corrections``' interpolation (0 at a grid epoch and across a heading reset)."""
    k = np.searchsorted(grid_t, t_out, side="right") - 1
    k = np.clip(k, 0, grid_t.size - 1)
    at_grid = np.isclose(t_out, grid_t[k], rtol=0, atol=1e-12)
    kn = np.minimum(k + 1, grid_t.size - 1)
    span = np.where(kn > k, grid_t[kn] - grid_t[k], 1.0)
    al = np.where(at_grid | ~np.isnan(reset_at[kn]), 0.0, (t_out - grid_t[k]) / span)
    return k, kn, al


def mean_weights(grid_t: FloatArray, t_out: FloatArray, reset_at: FloatArray) -> FloatArray:
    """Weights w (K,) on the grid epochs with Σ_k w_k e_k = the mean over the output epochs of
    ``smooth_corrections``' interpolated error (the shifts c_k are constants: no variance)."""
    k, kn, al = _interp(grid_t, t_out, reset_at)
    w = np.bincount(k, 1.0 - al, grid_t.size) + np.bincount(kn, al, grid_t.size)
    return w / t_out.size


def smooth_corrections(grid_t: FloatArray, t_out: FloatArray, corr: FloatArray,
                       reset_at: FloatArray, es: FloatArray) -> FloatArray:
    """Smoothed error estimate at every output epoch (N_out, 21), estimated minus true.

    At a grid epoch it is ê^s_k; inside (t_k, t_{k+1}) it is interpolated linearly between
    ê^s_k (after the update at t_k) and ê^s_{k+1} + c_{k+1} (the same error relative to the
    un-updated nominal state that runs up to t_{k+1}); across a heading reset it is held.
    """
    k, kn, al = _interp(grid_t, t_out, reset_at)
    al = al[:, None]
    return (1.0 - al) * es[k] + al * (es[kn] + corr[kn])


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
    par2[:, PGE:PGE + 3] -= e[:, IGE:IGE + 3]
    return lla2, vel2, q2, par2
