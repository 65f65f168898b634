"""The running linearisation point of ``graph-isam2``'s online pass (``RunningStates``): the
keyframe states as last estimated, each new keyframe's variables predicted from them with
the factors that create them, and the read-back of the keyframes iSAM2 touched."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....sensors.noise import gm_transition
from ..model.cpp_factors import (
    bias_link,
    bias_step,
    gap_factors,
    gap_start_states,
    gm_factor,
    gnss_gm_factor,
    imu_factor,
    keyframe_fixes,
    zupt_factor,
)
from ..model.problem import Problem, gravity_delta, noise, preintegrate
from .relin import marked_keyframes, read_states, state_keys
from .setup import segment_span


class RunningStates:
    """The keyframe states of one online pass over ``P`` as last estimated: rot, pos, vel,
    bias, cb and gg (the GNSS error state G(k), (K,) for the height alone), together
    ``arrays``; the segments' (s, τd) ``cal`` and the accelerometer scale factors ``ka``.
    ``init``: the initial states; ``causal``: keyframe 0 from ``P.start0``. ``rw_idx``:
    iSAM2 indices of the K / A segment random walks; ``gap_prior_idx``: interval → iSAM2
    index of its online gap prior (both replaced by the final rounds)."""

    def __init__(self, P: Problem, seg: np.ndarray, init: tuple[Any, Any, Any],
                 causal: bool) -> None:
        self.P, self.seg = P, seg
        self.has_baro = P.drive.baro is not None
        nk = P.n_kf
        self.rot, self.pos, self.vel = np.zeros((nk, 3, 3)), np.zeros((nk, 3)), np.zeros((nk, 3))
        gm_dim = 1 if P.gm is None else P.gm.dim
        self.bias, self.cb = np.zeros((nk, 6)), np.zeros(nk)
        self.gg = np.zeros(nk) if gm_dim == 1 else np.zeros((nk, gm_dim))
        self.arrays = (self.rot, self.pos, self.vel, self.bias, self.cb, self.gg)
        self.cal = {0: np.array([0.0, P.pri["tau0"]])}
        rot_i, pos_i, vel_i = init
        st0 = P.start0
        if causal:
            self.rot[0], self.pos[0], self.vel[0] = st0.rot, st0.pos, st0.vel
        else:
            self.rot[0], self.pos[0], self.vel[0] = rot_i[0], pos_i[0], vel_i[0]
        self.gap_states = gap_start_states(P, rot_i, pos_i, vel_i) if P.gap.any() else None
        self.rw_idx: list[int] = []
        self.rw_at: list[int] = []  # their positions in the update's new factors, until it
        # the online gap priors: (interval, index in the update's new factors) until the
        # update, then interval → iSAM2 factor index (swapped by the final rounds)
        self.gap_prior_at: list[tuple[int, int]] = []
        self.gap_prior_idx: dict[int, int] = {}
        self.dg_kf = np.zeros((nk, 3))  # gravity anomaly at each keyframe, once (terms)
        self.pims: list[Any] = []
        self.calib_rw = np.asarray(P.cfg.calib_rw, float)
        self.s_max = 0.0  # the largest |s| of the online pass (sensors.baro scale check)
        self.b_last = 0  # the last B(k) in iSAM2: B(k), interval k's bias, enters with it
        self.ka = np.zeros(3)  # the accelerometer scale factors as last estimated (P.ka)
        # k_a, like (s, τd), is one variable per segment, A(j), linked by a random walk of
        # root PSD accel_scale_rw·σ_ka (a global A in every bias link put it in every
        # clique: 1800 s hill-drive online pass 35 → 47 s)
        self.ka_rw = P.cfg.accel_scale_rw * (P.ka.sd if P.ka is not None else 0.0)

    def a_keys(self, m: int) -> tuple[int, int]:
        return A(int(self.seg[m])), A(int(self.seg[m + 1]))

    def calibration(self) -> dict[int, np.ndarray] | None:
        """The segments' (s, τd) when the drive has a barometer, else None."""
        return self.cal if self.has_baro else None

    def new_bias(self, nv: Any, nf: Any, k: int) -> None:
        """B(k) and its link from B(k−1) (``bias_link``: with the scale factors it needs ā_k,
        known once interval k is preintegrated), predicted from B(k−1)."""
        P, bias = self.P, self.bias
        dt_b = float(P.t_kf[k] - P.t_kf[k - 1])
        phi = bias_step(P.imu_spec, dt_b)[0]  # the link's mean: b(k) = φ·b(k−1)
        bias[k] = phi * bias[k - 1]
        if P.ka is not None:
            bias[k, 0:3] += (P.ka.f_mean[k] - phi[0:3] * P.ka.f_mean[k - 1]) * self.ka
        nv.insert(B(k), gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6]))
        nf.add(bias_link(P, k - 1, dt_b, self.a_keys(k - 1)))
        self.b_last = k

    def predict(self, k: int, nf: Any, nv: Any) -> None:
        """Interval k's IMU factor (or, across a logging gap, the gap's factors) and keyframe
        k + 1 at its prediction, which is its linearisation point; its preintegration is
        kept (``pims``)."""
        P, rot, pos, vel, bias = self.P, self.rot, self.pos, self.vel, self.bias
        dg = gravity_delta(P, pos[k:k + 1])[0]
        self.dg_kf[k] = dg
        if self.b_last < k:
            self.new_bias(nv, nf, k)
        b_k = gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6])
        pim = preintegrate(P, k, rot[k], dg, b_k)
        self.pims.append(pim)
        if P.gap[k]:  # its factors link B(k) to B(k+1): B(k+1) enters now
            # the new keyframe and its re-alignment prior from iSAM2's estimate (the data up
            # to now); the final rounds swap the prior for graph-batch's, built from the
            # initial states, so that both smoothers' final answers solve one problem
            x1, v1, gap_f = gap_factors(P, k, rot, pos, vel, self.a_keys(k))
            nv.insert(X(k + 1), x1)
            nv.insert(V(k + 1), v1)
            nv.insert(B(k + 1), b_k)
            self.b_last = k + 1
            self.gap_prior_at.append((k, nf.size()))  # gap_f[0], the prior
            for f in gap_f:
                nf.add(f)
        else:
            nav = pim.predict(gtsam.NavState(gtsam.Rot3(rot[k]), pos[k], vel[k]), b_k)
            nv.insert(X(k + 1), nav.pose())
            nv.insert(V(k + 1), nav.velocity())
            nf.add(imu_factor(k, pim))
        x_new = nv.atPose3(X(k + 1))
        rot[k + 1], pos[k + 1] = x_new.rotation().matrix(), x_new.translation()
        vel[k + 1], bias[k + 1] = nv.atVector(V(k + 1)), bias[k]
        self.cb[k + 1] = self.cb[k]

    def keyframe_fixes(self, k: int, nf: Any, nv: Any) -> list[tuple[int, int]]:
        """Keyframe k + 1's GNSS fixes, or its GNSS error state G and link (the fix on
        keyframe k + 1 then ends interval k's rows), and its zero-velocity prior inside a
        standstill. Returns (fix, index in ``nf``) pairs."""
        P = self.P
        fix_at: list[tuple[int, int]] = []
        if P.gm is None:
            for i, f in keyframe_fixes(P, k + 1):
                fix_at.append((i, nf.size()))
                nf.add(f)
        else:
            dt = float(P.t_kf[k + 1] - P.t_kf[k])
            self.gg[k + 1] = self.gg[k] * gm_transition(dt, P.gm.tau_s)
            nv.insert(G(k + 1), np.array(self.gg[k + 1], ndmin=1))
            nf.add(gnss_gm_factor(k, dt, P.gm))
        if P.zupt_kf[k + 1]:  # a standstill decided from the data up to t_{k+1}
            nf.add(zupt_factor(P, k + 1))
        return fix_at

    def new_states(self, k: int, nf: Any, nv: Any) -> None:
        """Keyframe k + 1's baro bias C and link, and a new segment's (s, τd) K and k_a A
        with their random walks."""
        P, seg = self.P, self.seg
        dt = float(P.t_kf[k + 1] - P.t_kf[k])
        new_seg = seg[k + 1] != seg[k]
        j = int(seg[k + 1])
        if self.has_baro:
            nv.insert(C(k + 1), np.array([self.cb[k]]))
            nf.add(gm_factor(k, dt, P.pri))
            if new_seg:
                self.cal[j] = self.cal[j - 1].copy()
                nv.insert(K(j), self.cal[j])
                span = segment_span(P, seg, j)
                self.rw_at.append(nf.size())  # its index is recorded: the final rounds
                nf.add(gtsam.BetweenFactorVector(K(j - 1), K(j), np.zeros(2),  # remove it
                                                 noise(self.calib_rw * np.sqrt(span))))
        if P.ka is not None and new_seg:
            nv.insert(A(j), self.ka)
            self.rw_at.append(nf.size())
            nf.add(gtsam.BetweenFactorVector(A(j - 1), A(j), np.zeros(3), noise(
                [self.ka_rw * np.sqrt(segment_span(P, seg, j))] * 3)))

    def record(self, new_idx: Any, offset: int) -> None:
        """iSAM2 indices of the update's random walks and gap priors (its new factors after
        the first ``offset``)."""
        self.rw_idx += [int(new_idx[offset + i]) for i in self.rw_at]
        self.rw_at = []
        self.gap_prior_idx.update((kk, int(new_idx[offset + i])) for kk, i in self.gap_prior_at)
        self.gap_prior_at = []

    def forget(self, gone: set[int]) -> None:
        """Factors ``gone`` left iSAM2 (``window``): no longer the final rounds' to replace."""
        self.rw_idx = [i for i in self.rw_idx if i not in gone]
        self.gap_prior_idx = {kk: i for kk, i in self.gap_prior_idx.items() if i not in gone}

    def read_back(self, isam: Any, ures: Any, k: int, floor: int) -> np.ndarray:
        """After an update in the pass at keyframe k + 1 (``ures``: its ISAM2Result): the
        keyframes iSAM2 marked, and the states of keyframes k − 1 … k + 1 and of the marked
        ones and their neighbours (from ``floor`` on) read into the arrays."""
        marked = marked_keyframes(ures.getMarkedKeys())
        read = np.r_[np.arange(max(k - 1, 0), k + 2), marked - 1, marked, marked + 1]
        keys_k = np.unique(read[(read >= floor) & (read <= k + 1)])
        read_states(isam.calculateEstimate(state_keys(keys_k, self.P, self.b_last)), keys_k,
                    self.arrays, self.P, self.b_last)
        return marked

    def read_calibration(self, isam: Any, k: int, first_seg: int) -> None:
        """The (s, τd) of keyframe k + 1's segment and the one before (from ``first_seg``),
        and its k_a."""
        if self.has_baro:
            j = int(self.seg[k + 1])
            for jj in range(max(j - 1, first_seg), j + 1):
                self.cal[jj] = isam.calculateEstimateVector(K(jj))
            self.s_max = max(self.s_max, abs(float(self.cal[j][0])))
        if self.P.ka is not None:
            self.ka = isam.calculateEstimateVector(A(int(self.seg[k + 1])))
