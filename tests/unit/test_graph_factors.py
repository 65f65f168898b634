"""Finite-difference checks of the custom graph terms (graph_factors) and frame helpers."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.graph.model import interval_factors as gf
from vnav_graph.estimators.graph.model.dense_increments import dense_preintegration
from vnav_graph.geo.earth import gravity
from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.nav.rotations import so3_exp

ORIGIN = np.array([np.radians(47.0), np.radians(11.0), 500.0])


def _setup(seed=0):
    """Random IMU over 4 keyframes of 1 s at 100 Hz and a random linearisation point."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 3.0 + 1e-9, 0.01)
    gyro = 0.2 * rng.normal(size=(t.size, 3))
    accel = np.array([0.5, -0.3, -9.8]) + rng.normal(size=(t.size, 3))
    kf = gf.keyframe_indices(t, 1.0)
    dense = dense_preintegration(t, gyro, accel, kf)
    nk = kf.size
    rot = np.array([so3_exp(rng.normal(size=3)) for _ in range(nk)])
    pos = np.array([[100.0 * k, 50.0 * k, -20.0 * k] for k in range(nk)]) + rng.normal(
        size=(nk, 3))
    vel = rng.normal(size=(nk, 3))
    st = gf.KeyframeStates(rot, pos, vel, 0.05 * rng.normal(size=(nk, 3)), rng.normal(size=nk),
                           np.full(nk, 0.02), np.full(nk, 0.15),
                           np.array([0.0, 0.0, 9.8]) + 0.01 * rng.normal(size=(nk, 3)))
    return dense, st, rng


def _perturb(st, col, eps, k):
    """Apply a perturbation of column ``col`` of group k (Pose3 chart: R Exp(ω), p + R v)."""
    rot, pos = st.rot.copy(), st.pos.copy()
    bb, s, tau = st.baro_bias.copy(), st.scale.copy(), st.latency.copy()
    ba = st.bias_accel.copy()
    if col >= gf.N_CORE:
        ba[k, col - gf.N_CORE] += eps
    elif col < 12:
        j = k + (col // 6)
        c = col % 6
        d = np.zeros(3)
        d[c % 3] = eps
        if c < 3:
            rot[j] = rot[j] @ so3_exp(d)
        else:
            pos[j] = pos[j] + rot[j] @ d
    elif col == gf.COL_B0:
        bb[k] += eps
    elif col == gf.COL_B1:
        bb[k + 1] += eps
    elif col == gf.COL_S:
        s += eps
    else:
        tau += eps
    return gf.KeyframeStates(rot, pos, st.vel, ba, bb, s, tau, st.accel_t)


def _fd_check(make_rows, st, tol):
    rows = make_rows(st)
    for col in range(gf.N_COLS):
        for k in np.unique(rows.k):
            m = rows.k == k
            eps = 1e-4
            rp = make_rows(_perturb(st, col, eps, k)).r[m]
            rm = make_rows(_perturb(st, col, -eps, k)).r[m]
            fd = (rp - rm) / (2 * eps)
            an = rows.jac[m, col]
            scale = max(1.0, np.max(np.abs(fd)))
            np.testing.assert_allclose(an, fd, atol=tol * scale, err_msg=f"col {col} k {k}")


def test_baro_rows_jacobian_matches_finite_differences():
    dense, st, rng = _setup(1)
    # samples away from keyframe boundaries (the interval assignment must not change under
    # the ±1e-6 s latency perturbation)
    t_s = np.array([0.43, 0.77, 1.31, 1.58, 2.22, 2.64])
    z = 500.0 + rng.normal(size=t_s.size)

    def rows(s):
        # bias read at t_s − 0.15 s, the latency of the linearisation point (as in the solver)
        return gf.baro_rows(dense, s, t_s, z, 0.5, 500.0, ORIGIN, bias_lag=0.15)

    # 2e-3 relative: the latency column is the time derivative of an interpolant that is
    # piecewise linear between 100 Hz samples (slope vs mid-interval velocity)
    _fd_check(rows, st, 2e-3)
    _fd_check_strict(rows, st, exclude=(gf.COL_TAU,), tol=1e-4)


def _fd_check_strict(make_rows, st, exclude, tol):
    rows = make_rows(st)
    for col in set(range(gf.N_COLS)) - set(exclude):
        for k in np.unique(rows.k):
            m = rows.k == k
            eps = 1e-4
            fd = (make_rows(_perturb(st, col, eps, k)).r[m]
                  - make_rows(_perturb(st, col, -eps, k)).r[m]) / (2 * eps)
            # eps 1e-4: truncation O(eps²) ≈ 1e-8; the height conversion (pymap3d) has ≈ 1e-9 m
            # round-off or worse (iterative geodetic conversion), up to ≈ 5e-5 relative at
            # eps 1e-4 — hence tol 1e-4
            np.testing.assert_allclose(rows.jac[m, col], fd, atol=tol * max(1, np.abs(fd).max()),
                                       err_msg=f"col {col} k {k}")


@pytest.mark.parametrize("lever", [np.zeros(3), np.array([0.8, -0.3, -1.2])])
def test_gnss_rows_jacobian_matches_finite_differences(lever):
    dense, st, rng = _setup(2)
    t_g = np.array([0.3, 0.9, 1.45, 2.05, 2.7])
    pos = rng.normal(size=(5, 3)) * 10
    vel = rng.normal(size=(5, 3))
    sd = np.full((5, 3), 1.5)
    # the body rate at the fixes: the lever arm's velocity C(ω × l) (shared GNSS model)
    w = rng.normal(0.0, 0.3, (5, 3))

    def rows(s):
        return gf.gnss_rows(dense, s, t_g, pos, sd, vel, np.full((5, 3), 0.1), lever,
                            omega_b=w)

    _fd_check_strict(rows, st, exclude=(), tol=1e-4)
    if np.any(lever):  # the term is there: velocity rows differ from those without ω
        r0 = gf.gnss_rows(dense, st, t_g, pos, sd, vel, np.full((5, 3), 0.1), lever)
        assert np.max(np.abs(rows(st).r[15:] - r0.r[15:])) > 0.1


def test_interpolant_hits_keyframes_and_is_exact_for_constant_acceleration():
    """With zero rotation rate and constant specific force the interpolant reproduces the
    closed-form parabola p(t) = p_k + v_k τ + ½(a + R f) τ² at every sample time."""
    t = np.arange(0, 2.0 + 1e-9, 0.005)
    f = np.array([0.3, -0.2, -9.7])
    dense = dense_preintegration(t, np.zeros((t.size, 3)), np.tile(f, (t.size, 1)),
                                    gf.keyframe_indices(t, 1.0))
    rot = np.array([so3_exp(np.array([0.1, -0.2, 0.3]))] * 3)
    a = np.array([0.0, 0.0, 9.81])
    acc = a + rot[0] @ f
    v0 = np.array([10.0, -3.0, 1.0])
    p = np.array([v0 * tk + 0.5 * acc * tk**2 for tk in (0.0, 1.0, 2.0)])
    st = gf.KeyframeStates(rot, p, np.tile(v0, (3, 1)), np.zeros((3, 3)), np.zeros(3),
                           np.zeros(3), np.zeros(3), np.tile(a, (3, 1)))
    tq = np.array([0.0, 0.125, 0.5, 0.995, 1.0, 1.77, 2.0])
    k = np.clip(np.searchsorted(dense.t_kf, tq, side="right") - 1, 0, 1)
    ip = gf.interpolate(dense, st, tq, k)
    exact = v0 * tq[:, None] + 0.5 * acc * tq[:, None] ** 2
    # on the IMU grid, trapezoidal integration of a constant input is exact up to round-off
    np.testing.assert_allclose(ip["p"], exact, atol=1e-9)
    np.testing.assert_allclose(ip["v"], v0 + acc * tq[:, None], atol=1e-9)
    # off the grid Δp is interpolated linearly: error ≤ |a|·dt²/8 = 9.8·0.005²/8 ≈ 3.1e-5 m
    tq = np.array([0.1234, 1.4567])
    ip = gf.interpolate(dense, st, tq, np.array([0, 1]))
    exact = v0 * tq[:, None] + 0.5 * acc * tq[:, None] ** 2
    np.testing.assert_allclose(ip["p"], exact, atol=3.2e-5)


def test_gravity_and_height_helpers():
    """Closed forms: at the origin g_t = [0, 0, γ]; 10 km north the vertical tilts by
    ≈ 10 km / R about the east axis; ∂h/∂p_t matches finite differences of ned_to_lla."""
    g0 = gf.gravity_t(np.zeros((1, 3)), ORIGIN)[0]
    np.testing.assert_allclose(g0, [0, 0, gravity(ORIGIN[0], ORIGIN[2])], atol=1e-12)
    p = np.array([[10000.0, 0.0, 0.0]])
    g = gf.gravity_t(p, ORIGIN)[0]
    tilt = -g[0] / g[2]
    # meridian radius at 47° ≈ 6.368e6 m: tilt = 10 km / (R_N + h), to 0.5 %
    assert tilt == pytest.approx(10000.0 / 6.3685e6, rel=5e-3)
    pts = np.array([[3000.0, -4000.0, -200.0], [12000.0, 9000.0, 100.0]])
    h, up = gf.height_and_up(pts, ORIGIN)
    for i in range(3):
        d = np.zeros(3)
        d[i] = 0.01
        fd = (ned_to_lla(pts + d, ORIGIN)[:, 2] - ned_to_lla(pts - d, ORIGIN)[:, 2]) / 0.02
        # the height is smooth on the scale of centimetres: FD error ≈ 1e-9
        np.testing.assert_allclose(up[:, i], fd, atol=1e-7)
    np.testing.assert_allclose(lla_to_ned(ned_to_lla(pts, ORIGIN), ORIGIN), pts, atol=1e-6)


def test_group_information_equals_dense_normal_equations():
    """Λ_k = Σ JᵀJ and η_k = −Σ Jᵀr per group, equal to the dense sums (closed form)."""
    rng = np.random.default_rng(5)
    k = rng.integers(0, 4, 40)
    rows = gf.IntervalRows(k, rng.normal(size=40), rng.normal(size=(40, gf.N_COLS)))
    groups, lam, eta, cost = gf.group_information(rows)
    for gi, g in enumerate(groups):
        m = k == g
        np.testing.assert_allclose(lam[gi], rows.jac[m].T @ rows.jac[m], atol=1e-12)
        np.testing.assert_allclose(eta[gi], -rows.jac[m].T @ rows.r[m], atol=1e-12)
    assert cost == pytest.approx(0.5 * np.sum(rows.r**2), rel=1e-14)



def test_group_information_in_chunks_equals_one_block(monkeypatch):
    """Chunked padding gives the same Λ, η (to rounding: the zero padding changes BLAS's
    summation blocking), for sorted and unsorted rows."""
    rng = np.random.default_rng(9)
    k = np.sort(rng.integers(0, 23, 300))
    for kk in (k, rng.permutation(k)):
        rows = gf.IntervalRows(kk, rng.normal(size=300), rng.normal(size=(300, gf.N_COLS)))
        monkeypatch.setattr(gf, "GROUP_CHUNK", 10**6)
        one = gf.group_information(rows)
        monkeypatch.setattr(gf, "GROUP_CHUNK", 4)
        chunked = gf.group_information(rows)
        np.testing.assert_array_equal(one[0], chunked[0])
        for a, b in zip(one[1:3], chunked[1:3], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)
        assert one[3] == chunked[3]

def test_nearest_fix_gap_equals_the_brute_force_distance():
    """The initialiser's distance from each keyframe to the nearest GNSS fix (searchsorted,
    no (keyframes × fixes) matrix) equals the brute-force minimum, unsorted fixes included."""
    from vnav_graph.estimators.graph.model.initial_guess import nearest_gap

    rng = np.random.default_rng(3)
    for _ in range(100):
        fixes = rng.uniform(0.0, 100.0, rng.integers(1, 60))
        q = rng.uniform(-10.0, 110.0, rng.integers(1, 90))
        brute = np.min(np.abs(fixes[None, :] - q[:, None]), axis=1)
        np.testing.assert_array_equal(nearest_gap(fixes, q), brute)


def test_gap_interval_is_interpolated_linearly_and_its_jacobians_match():
    """An interval holding an IMU logging gap (``DenseIncrements.gap``) has no inertial motion
    to follow: a baro sample or fix there sees the straight line between the keyframes, the
    attitude of keyframe k and no accelerometer-bias dependence, whatever the one IMU
    "sample" spanning the gap says (on Loiter_RTL the crash transient: integrated over 24 s
    it put the first baro sample after the gap tens of metres off and pulled the graph's baro
    scale to −56 %)."""
    from dataclasses import replace

    dense, st, rng = _setup(3)
    dense_gap = replace(dense, gap=np.array([False, True, False]))
    # a transient inside interval 1 changes nothing there once it is marked as a gap
    g2 = 0.2 * rng.normal(size=(dense.t.size, 3))
    a2 = np.array([0.5, -0.3, -9.8]) + rng.normal(size=(dense.t.size, 3))
    a2[150] += 300.0
    crash = replace(dense_preintegration(dense.t, g2, a2, dense.kf_idx),
                    gap=dense_gap.gap)
    tq = np.array([1.0, 1.3, 1.77, 1.99])
    k = np.ones(tq.size, dtype=int)
    for d in (dense_gap, crash):
        ip = gf.interpolate(d, st, tq, k)
        al = (tq - 1.0)[:, None]
        np.testing.assert_allclose(ip["p"], (1 - al) * st.pos[1] + al * st.pos[2], atol=1e-9)
        np.testing.assert_allclose(ip["v"], np.tile(st.pos[2] - st.pos[1], (tq.size, 1)),
                                   atol=1e-9)
        np.testing.assert_allclose(ip["rot"], np.tile(st.rot[1], (tq.size, 1, 1)), atol=0)
    # the other intervals keep the inertial interpolant
    np.testing.assert_allclose(gf.interpolate(dense_gap, st, np.array([0.4]), np.array([0]))["p"],
                               gf.interpolate(dense, st, np.array([0.4]), np.array([0]))["p"])
    t_s = np.array([0.43, 1.31, 1.58, 2.22])
    z = 500.0 + rng.normal(size=t_s.size)

    def baro(s):
        return gf.baro_rows(crash, s, t_s, z, 0.5, 500.0, ORIGIN, bias_lag=0.15)

    rows = baro(st)
    assert np.all(rows.jac[rows.k == 1][:, gf.COL_BA] == 0.0)
    _fd_check(baro, st, 2e-3)
    t_g = np.array([0.3, 1.45, 2.05])

    def gnss(s):
        return gf.gnss_rows(crash, s, t_g, st.pos[[0, 1, 2]] + 2.0,
                            np.full((3, 3), 1.5), st.vel[[0, 1, 2]], np.full((3, 3), 0.1),
                            np.zeros(3))

    _fd_check_strict(gnss, st, exclude=(), tol=1e-4)


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_gnss_rows_with_the_gnss_error_state_match_finite_differences(dim):
    """With G(k) (the GNSS Gauss-Markov error on the axes ``GM_AXES[dim]``, linear between
    keyframes) the rows have 2·dim more columns; every column matches central differences,
    the G columns touch only their axes' position rows (1 − α, α over σ), and the first 19
    columns are those of the rows without G."""
    from dataclasses import replace

    from vnav_graph.sensors.gnss_model import GM_AXES

    dense, st0, rng = _setup(3)
    nk = st0.pos.shape[0]
    g0 = rng.normal(size=nk) if dim == 1 else rng.normal(size=(nk, dim))
    st = replace(st0, gnss_gm=g0)
    t_g = np.array([0.3, 0.9, 1.45, 2.05, 2.7])
    pos = rng.normal(size=(5, 3)) * 10
    vel = rng.normal(size=(5, 3))
    sd = np.full((5, 3), 1.5)
    lever = np.array([0.8, -0.3, -1.2])

    def rows(s):
        return gf.gnss_rows(dense, s, t_g, pos, sd, vel, np.full((5, 3), 0.1), lever)

    r = rows(st)
    assert r.jac.shape[1] == gf.n_cols_of(dim)
    if dim == 1:
        assert gf.n_cols_of(1) == 21 and gf.gm_cols(1) == (slice(19, 20), slice(20, 21))
    for col in range(gf.n_cols_of(dim)):
        for k in np.unique(r.k):
            m = r.k == k
            eps = 1e-4
            if col >= gf.N_COLS:
                g_p, g_m = st.gnss_gm.copy(), st.gnss_gm.copy()
                j = k + (col - gf.N_COLS) // dim
                ax = (col - gf.N_COLS) % dim
                if dim == 1:
                    g_p[j] += eps
                    g_m[j] -= eps
                else:
                    g_p[j, ax] += eps
                    g_m[j, ax] -= eps
                sp, sm = replace(st, gnss_gm=g_p), replace(st, gnss_gm=g_m)
            else:
                sp = replace(_perturb(st, col, eps, k), gnss_gm=st.gnss_gm)
                sm = replace(_perturb(st, col, -eps, k), gnss_gm=st.gnss_gm)
            fd = (rows(sp).r[m] - rows(sm).r[m]) / (2 * eps)
            np.testing.assert_allclose(r.jac[m, col], fd, atol=1e-4 * max(1, np.abs(fd).max()),
                                       err_msg=f"col {col} k {k}")
    n = 3 * t_g.size
    k_fix = gf.interval_of(dense.t_kf, t_g)
    alpha = (t_g - dense.t_kf[k_fix]) / (dense.t_kf[k_fix + 1] - dense.t_kf[k_fix])
    c0, c1 = gf.gm_cols(dim)
    g2 = st.gnss_gm.reshape(nk, dim)
    r0 = rows(st0)
    for j, ax in enumerate(GM_AXES[dim]):
        on = np.zeros(r.r.size, bool)
        on[ax:n:3] = True
        assert np.all(r.jac[~on][:, c0.start + j] == 0.0)
        np.testing.assert_allclose(r.jac[on][:, c0.start + j], (1 - alpha) / 1.5, rtol=1e-12)
        np.testing.assert_allclose(r.jac[on][:, c1.start + j], alpha / 1.5, rtol=1e-12)
        g_at = (1 - alpha) * g2[k_fix, j] + alpha * g2[k_fix + 1, j]
        np.testing.assert_allclose(r.r[:n][ax::3] - r0.r[:n][ax::3], g_at / 1.5, rtol=1e-9)
    np.testing.assert_allclose(r.jac[:, :gf.N_COLS], r0.jac, rtol=0, atol=1e-12)


def test_preintegrated_velocity_increment_exact_in_a_turn():
    """The ImuFactor's velocity increment over one keyframe interval against the closed form
    of a constant-rate turn: body specific force (a, 0, −g) while the body turns at ω about
    z gives Δv = (a·sin ωT/ω, a·(1 − cos ωT)/ω, −gT) in the keyframe's body frame. GTSAM's
    step rotates the force by the attitude at the step's start; without the ½(ω × f)Δt term
    of ``problem.preintegrate`` the increment is off by ≈ ½·ω·a·Δt·T (2.5 mm/s here, which
    over a 60 s outage grew to decimetres)."""
    import dataclasses

    import gtsam

    from vnav_graph.estimators.graph import GraphConfig
    from vnav_graph.estimators.graph.model.problem import preintegrate, setup
    from vnav_graph.simulation.scenario import simulate

    d = simulate("hill-drive", 0, duration_s=5.0)
    w, a, g = 0.5, 2.0, 9.8
    n = d.imu.t.size
    imu = dataclasses.replace(d.imu, gyro_b=np.tile([0.0, 0.0, w], (n, 1)),
                              accel_b=np.tile([a, 0.0, -g], (n, 1)))
    P = setup(d.replace(imu=imu), GraphConfig(gravity_correction=False))
    pim = preintegrate(P, 0, np.eye(3), np.zeros(3), gtsam.imuBias.ConstantBias())
    T = float(P.t_kf[1] - P.t_kf[0])
    exact = np.array([a * np.sin(w * T) / w, a * (1 - np.cos(w * T)) / w, -g * T])
    dt = float(np.median(np.diff(d.imu.t)))
    assert np.abs(pim.deltaVij() - exact).max() < 0.05 * 0.5 * w * a * dt * T
