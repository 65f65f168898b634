"""Post-smoothing GNSS gate of ``ekf-rts`` (``EkfConfig.post_gate``): the counterpart of the
graph's post-solve gate (``graph.model.problem.post_solve_rejections``).

After the forward pass and the RTS smoother, every fix the filter used any part of (its
position, or its velocity alone: a fix whose position was refused as a multipath fault still
gave its velocity) is compared with the smoothed trajectory: its whitened residual χ² —
position (antenna = IMU position + C l) and, when the receiver gives velocity, velocity, each
row divided by the fix's σ of the shared
sensor model (``sensors.model``) — is tested against the χ² quantile of 1 − (1 − p)² with
p = ``EkfConfig.post_gate_prob`` (the graph's ``gnss_gate_prob``, 0.9999) and 3 (6 with
velocity) degrees of freedom: the graph's rule
(the squared tail probability: a false rejection costs a whole re-run, a glitch has χ² in
the thousands either way). Fixes above it are removed from the drive and the forward and RTS
passes are run again, at most ``post_gate_rounds`` times; nothing is removed when none or
every fix fails. With the Gauss-Markov GNSS error state (``sensors.gnss_model``) the residual
is z − (r + C l + ê) with ê the smoothed error state at the fix (``info["gnss_gm_at_fixes"]``)
and each row is divided by the white rest of the fix's σ, as in the graph's gate: that σ
alone without ê (0.5 m of the urban receiver's 2.55 m) refused most fixes of a correlated
drive. The residual of a fix that took part in the fit is smaller than its
innovation, so the gate is conservative (Groves §17.3).

Huber weights from the smoothed residuals (``EkfConfig.post_huber_rounds``, with a Huber loss
on the GNSS fixes). The forward filter weighs a fix by its innovation, w = min(1, k/e), e =
√NIS against the prediction; the graph weighs it by its residual against the smoothed
solution, recomputed at every relinearisation (IRLS). The two differ where the prediction is
weak: after a GNSS outage the covariance is large, the first fixes of a multipath burst get
w = 1 in the forward pass and the smoothed trajectory follows them (urban-dense seed 1: 5 m
off over 15 s with a velocity 5 σ off), while the graph, whose residual is taken against the
whole drive, down-weights them. After the gate rounds each used fix gets the graph's weights,
w_p = min(1, k_p/e_p) of its whitened position residual norm e_p (3 rows, white σ, ê
included) and w_v of its velocity residual, its σ is divided by √w (``huber_sd``: the white
part only, the Gauss-Markov part stays, so ``GnssGM.split`` returns white/√w; a part the
forward χ² gate refused keeps its σ, which would otherwise widen that gate for exactly the
outliers it refused: on a 2 Hz urban variant a burst then pulled the track 23 m), and the
forward and RTS passes run again with the forward Huber loss off for the fixes (one weight
per fix, as in the graph; the χ² gates stay). The filter's covariance is then computed with
the down-weighted R, as the graph's is from its re-weighted information.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ...geo.earth import radii
from ...geo.frames import quat_to_mat
from ...sensors.gnss_model import GnssGM
from ...sensors.model import SensorModel
from ...types import Drive, Estimate
from ...types.streams import FloatArray
from ..robust import post_gate_threshold, weight_and_loss
from .settings import EkfConfig


def fix_chi2(drive: Drive, est: Estimate, model: SensorModel,
             g_latency: float) -> tuple[FloatArray, int]:
    """Whitened residual χ² (G,) of every GNSS fix against the smoothed trajectory of
    ``est`` (module docstring) and its degrees of freedom."""
    c2p, c2v = fix_chi2_parts(drive, est, model, g_latency)
    return (c2p, 3) if c2v is None else (c2p + c2v, 6)


def fix_chi2_parts(drive: Drive, est: Estimate, model: SensorModel, g_latency: float
                   ) -> tuple[FloatArray, FloatArray | None]:
    """``fix_chi2``'s two parts: the position's χ² (G,) and the velocity's (G,), None when
    the receiver gives no velocity."""
    gnss, traj = drive.gnss, est.trajectory
    assert gnss is not None and model.gnss_pos_sd is not None
    tg = gnss.t - g_latency
    lat = np.interp(tg, traj.t, traj.lla[:, 0])
    lon = np.interp(tg, traj.t, traj.lla[:, 1])
    h = np.interp(tg, traj.t, traj.lla[:, 2])
    j = np.clip(np.searchsorted(traj.t, tg), 0, traj.t.size - 1)
    lever = np.asarray(gnss.lever_arm_b, dtype=float)
    d_n = np.einsum("kij,j->ki", quat_to_mat(traj.q_nb[j]), lever)
    rn, re = radii(lat)
    res = np.column_stack([(gnss.lla[:, 0] - lat) * (rn + h) - d_n[:, 0],
                           (gnss.lla[:, 1] - lon) * (re + h) * np.cos(lat) - d_n[:, 1],
                           -(gnss.lla[:, 2] - h) - d_n[:, 2]])
    ge = est.info.get("gnss_gm_at_fixes")
    if ge is not None:  # z_p = r + C l + e: the smoothed error state is part of the prediction
        res = res - ge
    c2p = np.sum((res / model.gnss_pos_sd) ** 2, axis=1)
    if gnss.vel_n is None or model.gnss_vel_sd is None:
        return c2p, None
    vel = np.column_stack([np.interp(tg, traj.t, traj.vel_n[:, a]) for a in range(3)])
    return c2p, np.sum(((gnss.vel_n - vel) / model.gnss_vel_sd) ** 2, axis=1)


def huber_weights(c2: FloatArray, k: float) -> FloatArray:
    """Huber's IRLS weight min(1, k/e) of each Mahalanobis norm e = √χ² (``estimators.robust``,
    the graphs' loss; ``ekf.model.huber_weight`` is the forward filter's scalar kernel of it);
    all 1 for k ≤ 0 (no loss)."""
    e = np.sqrt(np.maximum(np.asarray(c2, dtype=float), 0.0))
    if k <= 0:
        return np.ones(e.size)
    return weight_and_loss(e, "huber", k)[0]


def huber_sd(pos_sd: FloatArray, w: FloatArray, gm: GnssGM | None) -> FloatArray:
    """The receiver σ (N, 3) [m] whose white part is that of ``pos_sd`` over √w (N,): with
    the Gauss-Markov state ``gm`` √(white²/w + σ_gm²) on its axes, so that ``gm.split``
    of the result is white/√w; elsewhere σ/√w."""
    s = np.asarray(pos_sd, dtype=float) / np.sqrt(w)[:, None]
    if gm is None:
        return s
    white = gm.split(np.asarray(pos_sd, dtype=float)) / np.sqrt(w)[:, None]
    for a, sg in zip(gm.axes, gm.sd, strict=True):
        s[:, a] = np.sqrt(white[:, a] ** 2 + float(sg) ** 2)
    return s


def reweighted(drive: Drive, est: Estimate, model: SensorModel, g_latency: float,
               cfg: EkfConfig) -> tuple[Drive, FloatArray]:
    """``drive`` with each fix's σ divided by the square root of its Huber weights from its
    residual against ``est`` (module docstring), and the position weights (G,)."""
    gnss = drive.gnss
    assert gnss is not None
    c2p, c2v = fix_chi2_parts(drive, est, model, g_latency)
    kp, kv, _ = cfg.huber_k()
    # a part the forward gate refused keeps its σ: its weight would widen that gate for it
    wp = np.where(np.isin(gnss.t, est.info["gnss_rejected_t"]), 1.0, huber_weights(c2p, kp))
    vel_sd = gnss.vel_sd
    if c2v is not None and vel_sd is not None:
        wv = np.where(np.isin(gnss.t, est.info["gnss_unused_t"]), 1.0, huber_weights(c2v, kv))
        vel_sd = np.asarray(vel_sd, dtype=float) / np.sqrt(wv)[:, None]
    g = replace(gnss, pos_sd=huber_sd(gnss.pos_sd, wp, cfg.gnss_gm), vel_sd=vel_sd)
    return drive.replace(gnss=g), wp


def misfits(drive: Drive, est: Estimate, model: SensorModel, g_latency: float,
            used: np.ndarray, gate_prob: float) -> np.ndarray:
    """Mask (G,) of the used fixes that fail the post-smoothing gate; all False when none or
    every used fix fails (module docstring)."""
    c2, dof = fix_chi2(drive, est, model, g_latency)
    bad = used & (c2 > post_gate_threshold(gate_prob, dof))
    if bad.sum() == used.sum():
        return np.zeros_like(bad)
    return bad


def warning(name: str, removed: int, rounds: int, gate_prob: float) -> str:
    """The user-facing line of a post-smoothing gate that removed fixes."""
    return (f"{name}: {removed} GNSS fixes did not fit the smoothed trajectory (whitened "
            f"χ² above the {1.0 - (1.0 - gate_prob) ** 2:.8g} quantile) and were removed; "
            f"the forward and RTS passes were run again ({rounds} round"
            f"{'s' if rounds != 1 else ''})")


def regated(drive: Drive, est: Estimate, model: SensorModel, g_latency: float, cfg: EkfConfig,
            name: str, smooth: Callable[[Drive], tuple[SensorModel, Estimate]],
            t0: float, smooth_weighted: Callable[[Drive], Estimate] | None = None
            ) -> Estimate:
    """The post-smoothing gate rounds (module docstring) from the smoothed ``est`` of
    ``drive`` (``model``: its sensor model); ``smooth`` re-runs the forward and RTS passes on a
    drive and returns its sensor model and estimate. ``info`` gets
    ``gnss_rejected_postsmooth`` (fixes removed, also counted in ``gnss_rejected`` and
    listed in ``gnss_rejected_t``) and ``post_gate_rounds``; a warning when any was removed.
    ``smooth_weighted`` (the passes with the forward GNSS Huber loss off) then runs the
    ``post_huber_rounds`` (``huber_rounds``)."""
    assert drive.gnss is not None
    keep = np.ones(drive.gnss.t.size, dtype=bool)
    rounds = 0
    for _ in range(cfg.post_gate_rounds):
        sub = drive if keep.all() else drive.replace(gnss=drive.gnss.select(keep))
        assert sub.gnss is not None
        # a fix whose position the filter refused may still have given it its velocity: it is
        # tested too (the joint χ² has its position residual), as the graph tests every fix
        used = ~np.isin(sub.gnss.t, est.info["gnss_unused_t"])
        bad = misfits(sub, est, model, g_latency, used, cfg.post_gate_prob)
        if not bad.any():
            break
        keep[np.flatnonzero(keep)[bad]] = False
        rounds += 1
        model, est = smooth(drive.replace(gnss=drive.gnss.select(keep)))
    removed = int((~keep).sum())
    if smooth_weighted is not None:
        est = huber_rounds(drive.replace(gnss=drive.gnss.select(keep)), est, model,
                           g_latency, cfg, smooth_weighted)
    info = dict(est.info)
    info.update(gnss_rejected_postsmooth=removed, post_gate_rounds=rounds,
                gnss_rejected=int(info["gnss_rejected"]) + removed,
                gnss_rejected_t=np.sort(np.r_[info["gnss_rejected_t"], drive.gnss.t[~keep]]))
    if removed:
        info["warnings"] = [*(info.get("warnings") or []),
                            warning(name, removed, rounds, cfg.post_gate_prob)]
    return est.replace(info=info, runtime_s=time.perf_counter() - t0)


def huber_rounds(drive: Drive, est: Estimate, model: SensorModel, g_latency: float,
                 cfg: EkfConfig, smooth_weighted: Callable[[Drive], Estimate]) -> Estimate:
    """``cfg.post_huber_rounds`` passes with the fixes' Huber weights from their residuals
    against the previous smoothed estimate (module docstring; ``model``: the unweighted
    sensor model whose σ whitens the residuals). ``info["post_huber"]``: rounds, the fixes
    down-weighted (position weight < 1) and the smallest position weight of the last round."""
    wp = np.ones(0)
    for _ in range(cfg.post_huber_rounds):
        weighted, wp = reweighted(drive, est, model, g_latency, cfg)
        est = smooth_weighted(weighted)
    info = {**est.info, "post_huber": {"rounds": cfg.post_huber_rounds,
                                       "downweighted": int(np.sum(wp < 1.0)),
                                       "weight_min": float(wp.min()) if wp.size else None}}
    return est.replace(info=info)
