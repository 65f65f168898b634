"""Unit tests of the EKF kernels and the alignment helpers (closed forms, equivalences)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.alignment import level_tilt_bias_jacobian
from vnav_graph.geo.earth import gravity
from vnav_graph.geo.frames import attitude_error_n, quat_to_mat, rph_to_quat
from vnav_graph.nav.levelling import coarse_level


def test_coarse_level_closed_form():
    for rph in ([0.1, -0.05, 1.0], [-0.3, 0.2, -2.0]):
        c = quat_to_mat(rph_to_quat(rph)[0])
        f_b = c.T @ np.array([0.0, 0.0, -9.81])
        roll, pitch = coarse_level(f_b)
        # exact inversion (round-off only)
        assert abs(roll - rph[0]) < 1e-12 and abs(pitch - rph[1]) < 1e-12


def test_level_tilt_bias_jacobian_matches_finite_difference():
    rph = np.array([0.05, -0.03, 0.7])
    q = rph_to_quat(rph)[0]
    c = quat_to_mat(q)
    g = float(gravity(0.8, 500.0))
    f_b = c.T @ np.array([0.0, 0.0, -g])
    m = level_tilt_bias_jacobian(c, g)
    dba = np.array([0.02, -0.03, 0.01])  # estimated minus true (bias left in f̃ = f − δb_a)
    roll, pitch = coarse_level(f_b - dba)
    q_lev = rph_to_quat([roll, pitch, rph[2]])[0]
    psi = attitude_error_n(q_lev[None], q[None])[0]
    # horizontal tilt error predicted to first order (error O(|δb_a|²/g²) ≈ 1e-5 rad);
    # the yaw row of M is zero by construction (levelling holds the yaw fixed)
    np.testing.assert_allclose(psi[:2], (m @ dba)[:2], atol=2e-5)


def test_transition_second_order_matches_expm():
    ing = np.zeros(km.NING)
    ing[0:9] = quat_to_mat(rph_to_quat([0.1, 0.05, 0.4])[0]).ravel()
    ing[9:12] = [1.0, -0.5, -9.8]
    ing[12:15] = [0.5, 0.3, -9.8]
    ing[15], ing[16], ing[17:20] = 0.8, 500.0, [20.0, 5.0, -1.0]
    f = km.build_f(ing, 600.0, 600.0, 1800.0, 300.0)
    dt = 0.1
    # Φ = I + FΔt + ½(FΔt)² has a truncation error of (‖F‖Δt)³/6 ≈ 1e-3 relative to the
    # biggest entries (‖F‖ ≈ 10 from the specific force), here below 2e-3 absolute
    np.testing.assert_allclose(km.transition(f, dt), expm(f * dt), atol=2e-3)


def test_joseph_scalar_update_equals_standard_form(rng):
    a = rng.normal(size=(km.NX, km.NX))
    p = a @ a.T + np.eye(km.NX)
    h = rng.normal(size=km.NX)
    r = 0.7
    y = 1.3
    p1 = p.copy()
    dx = np.zeros(km.NX)
    km.scalar_update(p1, dx, h, y, r)
    k = p @ h / (h @ p @ h + r)
    # with the optimal gain the Joseph form equals (I − K h) P (round-off only)
    np.testing.assert_allclose(p1, (np.eye(km.NX) - np.outer(k, h)) @ p, atol=1e-10)
    np.testing.assert_allclose(dx, k * y, atol=1e-12)


def test_pack_unpack_roundtrip(rng):
    a = rng.normal(size=(km.NX, km.NX))
    p = a + a.T
    v = np.empty(km.NPACK)
    km.pack(p, v)
    np.testing.assert_array_equal(km.unpack(v), p)


def test_heading_decoupling_and_reset_jacobian():
    ing = np.zeros(km.NING)
    ing[0:9] = np.eye(3).ravel()
    ing[9:12] = [2.0, 1.0, -9.8]
    ing[15], ing[16] = 0.8, 0.0
    ing[20] = 1.0  # heading unknown
    f = km.build_f(ing, np.inf, np.inf, np.inf, np.inf)
    # yaw error decoupled: exactly zero row and column
    assert np.all(f[8] == 0.0) and np.all(f[:, 8] == 0.0)
    j = km.reset_jacobian(0.3)
    psi = np.array([0.01, -0.02, 0.5])
    x = np.zeros(km.NX)
    x[6:9] = psi
    out = (j @ x)[6:9]
    # tilt rotated by R_z(Δ) (closed form), yaw error replaced (zero)
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_allclose(out, [c * psi[0] - s * psi[1], s * psi[0] + c * psi[1], 0.0])


def test_unpack_cov_is_the_leading_block_of_the_packed_covariance():
    # packed upper triangles of NX×NX matrices → their leading 18×18 blocks, symmetric; the
    # baro rows/columns NaN when the drive has no barometer (blocks of 4096 epochs: 5000
    # crosses one boundary)
    from vnav_graph.estimators.ekf.model import unpack_cov

    rng = np.random.default_rng(3)
    a = rng.normal(size=(5000, km.NX, km.NX))
    s = a @ a.transpose(0, 2, 1)
    iu, ju = np.triu_indices(km.NX)
    cov = unpack_cov(s[:, iu, ju], True)
    np.testing.assert_array_equal(cov, s[:, :18, :18])
    no_baro = unpack_cov(s[:, iu, ju], False)
    assert np.isnan(no_baro[:, 15:18]).all() and np.isnan(no_baro[:, :, 15:18]).all()
    np.testing.assert_array_equal(no_baro[:, :15, :15], s[:, :15, :15])


def test_rts_mean_weights_reproduce_the_mean_of_the_interpolated_errors():
    """``rts.mean_weights``: Σ_k w_k e_k equals the mean over the output epochs of what
    ``smooth_corrections`` interpolates (with the constant shifts c_k set to 0), across an
    uneven grid, output epochs on and between grid epochs, and a heading reset (held)."""
    from vnav_graph.estimators.ekf import rts

    rng = np.random.default_rng(3)
    grid_t = np.r_[0.0, 0.1, 0.2, 0.35, 0.5, 0.6, 1.6, 1.7]
    t_out = np.r_[np.arange(0.0, 0.6, 0.02), 0.6, 1.0, 1.2, 1.65, 1.7]
    reset_at = np.full(grid_t.size, np.nan)
    reset_at[3] = 0.2
    es = rng.normal(size=(grid_t.size, 4))
    w = rts.mean_weights(grid_t, t_out, reset_at)
    direct = rts.smooth_corrections(grid_t, t_out, np.zeros_like(es), reset_at, es).mean(0)
    assert w.sum() == pytest.approx(1.0)
    assert np.all(w >= 0)
    assert w @ es == pytest.approx(direct, abs=1e-12)
