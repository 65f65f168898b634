"""Reference ``gtsam.CustomFactor``s for the terms the graph smoothers evaluate themselves.

graph-batch and graph-isam2 do not hand these terms to GTSAM as factors: they compute the
residual rows and Jacobians in numpy / numba (``graph.model.interval_factors``) and
assemble the linear system. Each reference below is a small ``gtsam.CustomFactor`` written
from the physics in ``docs/design.md`` and the module docstrings, on GTSAM's variable types
(Pose3 X(k), ``imuBias.ConstantBias`` B(k), Vector C(k), K(0), G(k), H(0)), with Jacobians
from GTSAM's own chain rules (``Pose3.translation``/``rotation``, ``Rot3.rotate`` with
their Jacobian arguments). Its error never calls the product's row functions or sensor models
(``baro_rows``, ``gnss_rows``, ``interpolate``, ``baro_predict``, ``antenna_*``,
``mag_heading_row``); its height is pymap3d's, not ``geo.frames``. Its product inputs are
the IMU increments ΔR, Δv, Δp of ``DenseIncrements.at`` — the measurement of the term, as a
``PreintegratedImuMeasurements`` is that of ``gtsam.ImuFactor`` — and two constants, the
GNSS error state's axes ``GM_AXES`` and the gap's acceleration level ``GAP_ACCEL_LEVEL``.

Terms covered (the list follows the code: every term the graph linearises itself, and the
linear factors whose coefficients it computes). This module holds the terms through the
keyframe interpolant, each in an interval with IMU data and in one holding an IMU logging
gap (the straight line between the keyframes, attitude R_k, no accelerometer bias, σ widened
by the line's own ``bridge_sd``: ½aτ(T − τ) on positions, a|τ − T/2| on velocities):

1. baro sample through the keyframe interpolant (``baro_rows``), keys X(k), X(k+1), C(k),
   C(k+1), K(0) = (s, τd), B(k):
   e = h0 + (1+s)(h(p(t_s − τd)) − h0) + b(t_s − λ) − z, b linear between C(k), C(k+1),
   λ the bias read lag, a constant of the solve (the solver keeps it within
   ``GraphConfig.bias_lag_tol`` of τd; ``baro_rows`` docstring);
2. GNSS antenna position with a lever arm (``gnss_rows``), keys X(k), X(k+1), B(k):
   e = p(t) + R(t) l − z_p, R(t) = R_k ΔR(τ);
3. GNSS antenna velocity with a lever arm, same keys: e = v(t) + R(t)(ω × l) − z_v,
   v(t) = dp/dt of the interpolant;
4. 2 and 3 with the GNSS Gauss-Markov error state G(k), G(k+1) of dimension 1, 2, 3
   (position: + S((1−α) G_k + α G_{k+1}) on the axes ``GM_AXES``).

``test_reference_keyframe_factors.py`` holds the terms on keyframe variables: 5. the
magnetometer heading (``builtin_sensors.mag_heading_factor``), 6. the Gauss-Markov links
(``cpp_factors.gm_link``, ``gnss_gm_factor``), 7. the IMU bias link with and without
accelerometer scale factors (``cpp_factors.bias_link``).

Not covered: GTSAM's own factors (the IMU factor, priors, GPSFactorArm on keyframe epochs),
the gap factors (``cpp_factors.gap_factors``: GTSAM priors and BetweenFactors), and the GNSS
velocity row without the body rate (``omega_b`` None: the product leaves the lever arm's
rotation term out by design).

Interpolant (``interval_factors`` docstring), τ = t − t_k, T = t_{k+1} − t_k, α = τ/T:
p(t) = (1−α) p_k + α p_{k+1} + ½ a_k (τ² − τT) + R_k d,
d = Δp(τ) − ½τ² b_a − α (ΔP(T) − ½T² b_a); a_k (nav-frame acceleration not measured by
the IMU) is data held at the linearisation point, like the increments; the gyro bias does
not enter (documented as not modelled), so the gyro half of B(k)'s tangent has zero columns.

Mapping of the product's columns to GTSAM's tangent spaces (``_col_map``): the product's
pose columns are already the Pose3 chart (R ← R Exp(ω), p ← p + R v, ω then v; GTSAM's
Pose3 retraction equals it to first order, all a Jacobian sees), its
baro-bias, calibration and GNSS-error columns are the Vector variables' coordinates, and its
accelerometer-bias columns are the first three of ConstantBias' (accel, gyro) tangent. The
chain-rule matrix M is therefore a selection (identity blocks, zero gyro columns), and
J_gtsam = J_product · M. The product's rows are whitened (÷σ) with r = (prediction −
measurement)/σ; GTSAM's linearisation of the reference gives A = J/σ and b = −e/σ, so the
checks are A = J_product·M, b = −r and e = σ·r. A mapping that takes the product's pose
columns as (translation, rotation) fails (``test_the_comparison_detects_wrong_inputs``).
"""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pymap3d
import pytest
from gtsam.symbol_shorthand import B, C, G, K, X

from vnav_graph.estimators.graph import check_jacobians
from vnav_graph.estimators.graph.model import interval_factors as gf
from vnav_graph.estimators.graph.model.dense_increments import dense_preintegration
from vnav_graph.sensors.gnss_model import GM_AXES

ORIGIN = np.array([np.radians(47.0), np.radians(11.0), 500.0])
H0 = 500.0
SEEDS = (11, 12, 13)
# measured over these seeds, with and without a gap: errors agree to ≤ 2.9e-14 m (baro:
# bitwise), whitened Jacobians to ≤ 2.9e-14 (round-off); a wrong input is off by 0.19 … 12
ERR_RTOL = 1e-9  # errors: relative to the size of the measured quantity
JAC_TOL = 1e-9  # analytic Jacobians (GTSAM chain rules) against the product's


# --- the linearisation point ---------------------------------------------------------------

def _rot(rng: np.random.Generator) -> np.ndarray:
    return gtsam.Rot3.Expmap(rng.normal(size=3)).matrix()


def _state(seed: int, gm_dim: int = 0, gap: bool = False):
    """Random IMU over 4 keyframes of 1 s at 100 Hz and a random linearisation point;
    ``gap``: interval 1 holds an IMU logging gap (``DenseIncrements.gap``)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 3.0 + 1e-9, 0.01)
    gyro = 0.2 * rng.normal(size=(t.size, 3))
    accel = np.array([0.5, -0.3, -9.8]) + rng.normal(size=(t.size, 3))
    dense = dense_preintegration(t, gyro, accel, gf.keyframe_indices(t, 1.0))
    if gap:
        dense = replace(dense, gap=np.array([False, True, False]))
    nk = dense.t_kf.size
    pos = np.array([[100.0 * k, 50.0 * k, -20.0 * k] for k in range(nk)]) \
        + rng.normal(size=(nk, 3))
    gm = None
    if gm_dim:
        gm = rng.normal(size=nk) if gm_dim == 1 else rng.normal(size=(nk, gm_dim))
    st = gf.KeyframeStates(
        np.array([_rot(rng) for _ in range(nk)]), pos, rng.normal(size=(nk, 3)),
        0.05 * rng.normal(size=(nk, 3)), rng.normal(size=nk),
        np.full(nk, rng.uniform(-0.03, 0.03)), np.full(nk, rng.uniform(0.05, 0.25)),
        np.array([0.0, 0.0, 9.8]) + 0.01 * rng.normal(size=(nk, 3)), gm)
    return dense, st, rng


def _values(st: gf.KeyframeStates, rng: np.random.Generator) -> gtsam.Values:
    """The product's state as GTSAM variables (gyro biases random: they must not matter)."""
    v = gtsam.Values()
    for j in range(st.pos.shape[0]):
        v.insert(X(j), gtsam.Pose3(gtsam.Rot3(st.rot[j]), st.pos[j]))
        v.insert(B(j), gtsam.imuBias.ConstantBias(st.bias_accel[j], 0.01 * rng.normal(size=3)))
        v.insert(C(j), np.array([st.baro_bias[j]]))
        if st.gnss_gm is not None:
            v.insert(G(j), np.atleast_1d(st.gnss_gm[j]).astype(float))
    v.insert(K(0), np.array([st.scale[0], st.latency[0]]))
    return v


# --- the reference interpolant and factors ------------------------------------------------

class Interval:
    """Interval k of ``dense`` (its IMU increments are the term's measurement)."""

    def __init__(self, dense, k: int, accel_t: np.ndarray) -> None:
        self.dense, self.k = dense, k
        self.t_k = float(dense.t_kf[k])
        self.T = float(dense.t_kf[k + 1] - dense.t_kf[k])
        self.dp_end = np.array(dense.dp_end[k])
        self.a = np.array(accel_t[k])
        # an IMU logging gap: no inertial motion to follow (``interpolate``): the straight
        # line between the keyframes, attitude R_k, no accelerometer bias, a_k not applied
        self.gap = dense.gap is not None and bool(dense.gap[k])

    def bridge_sd(self, t: float) -> tuple[float, float]:
        """σ of the straight line inside a gap interval (position, velocity): an unknown
        acceleration A ~ N(0, a²) moves p(t) by ½A·τ(T − τ) and v(t) by A·(τ − T/2)."""
        if not self.gap:
            return 0.0, 0.0
        tau = float(np.clip(t - self.t_k, 0.0, self.T))
        a = gf.GAP_ACCEL_LEVEL
        return 0.5 * a * tau * (self.T - tau), a * abs(tau - 0.5 * self.T)

    def at(self, xk: gtsam.Pose3, xk1: gtsam.Pose3, ba: np.ndarray, t: float) -> dict:
        """p(t), v(t), R(t) and their Jacobians w.r.t. X_k, X_{k+1} (3×6) and b_a (3×3)."""
        dr, dv, dp = (x[0] for x in self.dense.at(np.array([t]), np.array([self.k])))
        tau, big_t = t - self.t_k, self.T
        al = tau / big_t
        end_c = self.dp_end - 0.5 * big_t**2 * ba
        d = dp - 0.5 * tau**2 * ba - al * end_c
        dvel = dv - tau * ba - end_c / big_t
        acc, imu = self.a, 1.0
        if self.gap:
            d, dvel, dr, acc, imu = np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), 0.0
        h_t0, h_t1, h_r0 = np.zeros((3, 6)), np.zeros((3, 6)), np.zeros((3, 6))
        p0, p1 = xk.translation(h_t0), xk1.translation(h_t1)
        rk = xk.rotation(h_r0)
        h_rd, h_d = np.zeros((3, 3)), np.zeros((3, 3))
        rd = rk.rotate(d, h_rd, h_d)
        h_rv, h_v = np.zeros((3, 3)), np.zeros((3, 3))
        rv = rk.rotate(dvel, h_rv, h_v)
        return {
            "p": (1 - al) * p0 + al * p1 + 0.5 * acc * (tau**2 - tau * big_t) + rd,
            "v": (p1 - p0) / big_t + acc * (tau - 0.5 * big_t) + rv,
            "R_k": rk, "dR": dr, "alpha": al, "H_rk": h_r0,
            "p_X0": (1 - al) * h_t0 + h_rd @ h_r0, "p_X1": al * h_t1,
            "p_ba": imu * 0.5 * tau * (big_t - tau) * h_d,
            "v_X0": -h_t0 / big_t + h_rv @ h_r0, "v_X1": h_t1 / big_t,
            "v_ba": imu * (0.5 * big_t - tau) * h_v,
        }


def height_and_up(p_t: np.ndarray) -> tuple[float, np.ndarray]:
    """Ellipsoidal height [m] of a tangent-NED point (pymap3d) and ∂h/∂p_t: the ellipsoid
    normal at the point's latitude and longitude, resolved in the tangent frame."""
    lat, lon, h = pymap3d.ned2geodetic(*p_t, *ORIGIN, deg=False)
    up_e = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    return float(h), np.array(pymap3d.ecef2nedv(*up_e, ORIGIN[0], ORIGIN[1], deg=False))


def _bias_block(h_ba: np.ndarray) -> np.ndarray:
    """A Jacobian w.r.t. b_a as one w.r.t. ConstantBias' (accel, gyro) tangent."""
    return np.hstack([h_ba, np.zeros((h_ba.shape[0], 3))])


def baro_reference(iv: Interval, t_s: float, z: float, sd: float, lag: float):
    """Reference baro factor on X(k), X(k+1), C(k), C(k+1), K(0), B(k) (term 1)."""
    k = iv.k
    a_b = float(np.clip((t_s - lag - iv.t_k) / iv.T, 0.0, 1.0))

    def error_func(this: gtsam.CustomFactor, v: gtsam.Values, jac: list | None) -> np.ndarray:
        kx0, kx1, kc0, kc1, kk, kb = this.keys()
        s, tau_d = v.atVector(kk)
        b = (1 - a_b) * v.atVector(kc0)[0] + a_b * v.atVector(kc1)[0]
        ip = iv.at(v.atPose3(kx0), v.atPose3(kx1),
                   v.atConstantBias(kb).accelerometer(), t_s - tau_d)
        h, up = height_and_up(ip["p"])
        e = H0 + (1 + s) * (h - H0) + b - z
        if jac is not None:
            g = (1 + s) * up[None, :]
            jac[0], jac[1] = g @ ip["p_X0"], g @ ip["p_X1"]
            jac[2], jac[3] = np.array([[1 - a_b]]), np.array([[a_b]])
            # ∂/∂τd: h(t_s − τd) moves with −v_up(t_s − τd)
            jac[4] = np.array([[h - H0, -(1 + s) * float(up @ ip["v"])]])
            jac[5] = _bias_block(g @ ip["p_ba"])
        return np.array([e])

    keys = [X(k), X(k + 1), C(k), C(k + 1), K(0), B(k)]
    # in a gap interval the straight line's own σ, at t_s (it must not move with τd)
    sd_eff = float(np.hypot(sd, iv.bridge_sd(t_s)[0]))
    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, sd_eff), keys, error_func)


def gnss_reference(iv: Interval, t: float, z: np.ndarray, sd: np.ndarray, lever: np.ndarray,
                   omega: np.ndarray | None, gm_dim: int):
    """Reference GNSS position (``omega`` None) or velocity factor on X(k), X(k+1), B(k)
    and, for a position with ``gm_dim`` > 0, G(k), G(k+1) (terms 2–4)."""
    k = iv.k

    def error_func(this: gtsam.CustomFactor, v: gtsam.Values, jac: list | None) -> np.ndarray:
        keys = this.keys()
        ip = iv.at(v.atPose3(keys[0]), v.atPose3(keys[1]),
                   v.atConstantBias(keys[2]).accelerometer(), t)
        arm_b = ip["dR"] @ (lever if omega is None else np.cross(omega, lever))
        h_arm, h_unused = np.zeros((3, 3)), np.zeros((3, 3))
        arm = ip["R_k"].rotate(arm_b, h_arm, h_unused)  # R_k ΔR l (or R_k ΔR (ω × l))
        q = "p" if omega is None else "v"
        e = ip[q] + arm - z
        j0 = ip[q + "_X0"] + h_arm @ ip["H_rk"]
        blocks = [j0, ip[q + "_X1"], _bias_block(ip[q + "_ba"])]
        if gm_dim:
            al = ip["alpha"]
            sel = np.zeros((3, gm_dim))
            for j, ax in enumerate(GM_AXES[gm_dim]):
                sel[ax, j] = 1.0
            e = e + sel @ ((1 - al) * v.atVector(keys[3]) + al * v.atVector(keys[4]))
            blocks += [(1 - al) * sel, al * sel]
        if jac is not None:
            for i, blk in enumerate(blocks):
                jac[i] = blk
        return e

    keys = [X(k), X(k + 1), B(k)] + ([G(k), G(k + 1)] if gm_dim else [])
    sd_eff = np.hypot(sd, iv.bridge_sd(t)[0 if omega is None else 1])
    return gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(sd_eff), keys, error_func)


# --- the comparison ------------------------------------------------------------------------

def _col_map(n_prod: int, blocks: list[tuple[int, int, int]], n_tan: int) -> np.ndarray:
    """M (n_prod, n_tan): product column c + i → tangent column t + i for each block
    (product first column c, tangent first column t, width)."""
    m = np.zeros((n_prod, n_tan))
    for c, t, w in blocks:
        m[c:c + w, t:t + w] = np.eye(w)
    return m


# baro: X_k (6), X_k+1 (6), C_k, C_k+1, K (s, τd), B_k (accel 3, gyro 3) = 22 tangent columns
BARO_MAP = _col_map(gf.N_COLS, [(0, 0, 12), (gf.COL_B0, 12, 1), (gf.COL_B1, 13, 1),
                                (gf.COL_S, 14, 2), (gf.COL_BA.start, 16, 3)], 22)
SWAPPED = [(0, 3, 3), (3, 0, 3), (6, 9, 3), (9, 6, 3)]  # (translation, rotation): wrong


def gnss_map(gm_dim: int, pose_blocks=((0, 0, 12),)) -> np.ndarray:
    """GNSS: X_k, X_k+1, B_k (accel, gyro), then G_k, G_k+1 (``gf.gm_cols``)."""
    c0, c1 = gf.gm_cols(gm_dim)
    blocks = [*pose_blocks, (gf.COL_BA.start, 12, 3)]
    if gm_dim:
        blocks += [(c0.start, 18, gm_dim), (c1.start, 18 + gm_dim, gm_dim)]
    return _col_map(gf.n_cols_of(gm_dim), blocks, 18 + 2 * gm_dim)


def compare(factor, values: gtsam.Values, r: np.ndarray, jac: np.ndarray, m: np.ndarray,
            scale: float) -> None:
    """Assert the reference factor's unwhitened error is σ·r (σ of the reference's noise
    model; to ``ERR_RTOL`` of ``scale``, the size of the measured quantity) and GTSAM's
    linearisation of it is the product's whitened rows: A = J·M, b = −r."""
    sd = factor.noiseModel().sigmas()
    e = factor.unwhitenedError(values)
    np.testing.assert_allclose(e, sd * r, rtol=0, atol=ERR_RTOL * scale, err_msg="error")
    a, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(b, -r, rtol=0, atol=ERR_RTOL * scale / np.min(sd),
                               err_msg="linearised b")
    want = jac @ m
    np.testing.assert_allclose(a, want, rtol=0, atol=JAC_TOL * max(1.0, np.abs(want).max()),
                               err_msg="Jacobian")


def _assert_own_jacobians(factor, values: gtsam.Values, eps: float = 1e-6,
                          tol: float = 1e-6) -> None:
    """The reference's analytic Jacobians against central differences (``check_jacobians``)."""
    chk = check_jacobians(factor, values, eps=eps, tol=tol)
    assert chk.ok, str(chk)


# --- baro -----------------------------------------------------------------------------------

# the delayed times t_s − τd (τd in 0.05 … 0.25 s) stay ≥ 0.06 s inside their interval: the
# reference keeps the interval of the linearisation point (as the product's rows do)
T_BARO = np.array([0.43, 0.77, 1.31, 1.58, 2.32, 2.64])
SD_BARO = 0.5


def _baro_case(seed: int, lat_sign: float = 1.0, scale_sign: float = 1.0, gap: bool = False,
               gap_prod: bool | None = None):
    """Reference factors, values and the product's rows (``gap_prod``: the product's gap
    flag, by default ``gap``)."""
    dense, st, rng = _state(seed, gap=gap)
    dense_prod = dense if gap_prod is None or gap_prod == gap else _state(seed)[0]
    z = H0 + 20.0 * rng.normal(size=T_BARO.size)
    # λ: the solver's bias read lag, within ``GraphConfig.bias_lag_tol`` (0.02 s) of τd
    lag = float(st.latency[0]) + 0.013
    st_prod = replace(st, latency=lat_sign * st.latency, scale=scale_sign * st.scale)
    rows = gf.baro_rows(dense_prod, st_prod, T_BARO, z, SD_BARO, H0, ORIGIN, bias_lag=lag)
    k_true = gf.interval_of(dense.t_kf, T_BARO - st.latency[0])
    factors = [baro_reference(Interval(dense, int(k), st.accel_t), float(ts), float(zi),
                              SD_BARO, lag) for ts, zi, k in zip(T_BARO, z, k_true, strict=True)]
    return factors, _values(st, rng), rows


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("gap", [False, True], ids=["imu", "gap"])
def test_baro_rows_equal_the_reference_factor(seed, gap):
    factors, values, rows = _baro_case(seed, gap=gap)
    assert np.sum(rows.k == 1) == 2  # two samples in interval 1 (a gap with ``gap``)
    assert rows.jac.shape == (T_BARO.size, gf.N_COLS)
    for i, f in enumerate(factors):
        # eps 1e-3: pymap3d's height has ≈ 1e-9 m round-off (1e-5 relative at eps 1e-4),
        # the truncation at 1e-3 is ≈ 2e-6 (measured over these seeds)
        _assert_own_jacobians(f, values, eps=1e-3, tol=1e-5)
        compare(f, values, rows.r[i:i + 1], rows.jac[i:i + 1], BARO_MAP, H0)


# --- GNSS ------------------------------------------------------------------------------------

T_GNSS = np.array([0.3, 0.9, 1.45, 2.05, 2.7])
LEVER = np.array([0.8, -0.3, -1.2])
SD_POS, SD_VEL = np.array([1.5, 1.2, 2.5]), np.array([0.1, 0.12, 0.2])


def _gnss_case(seed: int, lever: np.ndarray, gm_dim: int, lever_prod=None, omega_sign=1.0,
               gap: bool = False, gap_prod: bool | None = None):
    dense, st, rng = _state(seed, gm_dim, gap)
    dense_prod = dense if gap_prod is None or gap_prod == gap else _state(seed, gm_dim)[0]
    n = T_GNSS.size
    z_p = st.pos[gf.interval_of(dense.t_kf, T_GNSS)] + 30.0 * rng.normal(size=(n, 3))
    z_v = 10.0 * rng.normal(size=(n, 3))
    omega = rng.normal(0.0, 0.5, (n, 3))
    rows = gf.gnss_rows(dense_prod, st, T_GNSS, z_p, np.tile(SD_POS, (n, 1)), z_v,
                        np.tile(SD_VEL, (n, 1)), lever if lever_prod is None else lever_prod,
                        omega_b=omega_sign * omega)
    k = gf.interval_of(dense.t_kf, T_GNSS)
    pos_f, vel_f = [], []
    for i in range(n):
        iv = Interval(dense, int(k[i]), st.accel_t)
        pos_f.append(gnss_reference(iv, T_GNSS[i], z_p[i], SD_POS, lever, None, gm_dim))
        vel_f.append(gnss_reference(iv, T_GNSS[i], z_v[i], SD_VEL, lever, omega[i], 0))
    return pos_f, vel_f, _values(st, rng), rows, z_p


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("gm_dim", [0, 1, 2, 3])
@pytest.mark.parametrize("lever", [np.zeros(3), LEVER], ids=["no-lever", "lever"])
@pytest.mark.parametrize("gap", [False, True], ids=["imu", "gap"])
def test_gnss_rows_equal_the_reference_factors(seed, gm_dim, lever, gap):
    pos_f, vel_f, values, rows, z_p = _gnss_case(seed, lever, gm_dim, gap=gap)
    n = T_GNSS.size
    m_pos, m_vel = gnss_map(gm_dim), gnss_map(0)
    n_vel = gf.n_cols_of(0)
    scale = float(np.abs(z_p).max())
    for i in range(n):
        sp, sv = slice(3 * i, 3 * i + 3), slice(3 * n + 3 * i, 3 * n + 3 * i + 3)
        _assert_own_jacobians(pos_f[i], values)
        _assert_own_jacobians(vel_f[i], values)
        compare(pos_f[i], values, rows.r[sp], rows.jac[sp], m_pos, scale)
        # the velocity rows have no GNSS-error columns (zero in the product's)
        assert not np.any(rows.jac[sv, n_vel:])
        compare(vel_f[i], values, rows.r[sv], rows.jac[sv, :n_vel], m_vel, scale)


# --- the checks can fail -------------------------------------------------------------------

def _wrong(case: str) -> None:
    """Run one comparison with a deliberately wrong product-side input or mapping."""
    if case.startswith("baro"):
        gap = "gap" in case  # the reference's interval 1 is a gap, the product's is not
        factors, values, rows = _baro_case(SEEDS[0], -1.0 if "latency" in case else 1.0,
                                           -1.0 if "scale" in case else 1.0, gap, False)
        m = _col_map(gf.N_COLS, [*SWAPPED, (12, 12, 4), (16, 16, 3)], 22) \
            if "swapped" in case else BARO_MAP
        for i, f in enumerate(factors):
            compare(f, values, rows.r[i:i + 1], rows.jac[i:i + 1], m, H0)
    else:
        dense, st, _ = _state(SEEDS[0])
        lever_prod = st.rot[0] @ LEVER if "lever" in case else None  # arm resolved in t
        omega_sign = -1.0 if "omega" in case else 1.0
        pos_f, vel_f, values, rows, z_p = _gnss_case(SEEDS[0], LEVER, 0, lever_prod,
                                                     omega_sign, "gap" in case, False)
        n = T_GNSS.size
        for i in range(n):
            if "omega" in case:
                sv = slice(3 * n + 3 * i, 3 * n + 3 * i + 3)
                compare(vel_f[i], values, rows.r[sv], rows.jac[sv], gnss_map(0), 100.0)
            else:
                sp = slice(3 * i, 3 * i + 3)
                compare(pos_f[i], values, rows.r[sp], rows.jac[sp], gnss_map(0), 100.0)


WRONG = ["baro latency sign", "baro scale sign", "baro pose columns swapped",
         "baro gap not marked", "gnss lever in tangent frame", "gnss omega sign",
         "gnss gap not marked"]


@pytest.mark.parametrize("case", WRONG)
def test_the_comparison_detects_wrong_inputs(case):
    with pytest.raises(AssertionError):
        _wrong(case)
