"""The shared GNSS measurement model (``sensors.gnss_model``): its Jacobians against finite
differences, and the filter's row and the graph's factor built from it agreeing on one state.

Agreement: the EKF's nominal state (lla, C_nb, GNSS error ê) and the graph's keyframe k with
the tangent frame at that position (t = local NED there), a fix on keyframe k's epoch (α = 0:
the interpolant is X_k itself). Then the graph's whitened position residual times σ is the
filter's innovation, and its Jacobian columns are the filter's turned into the graph's
tangent coordinates: translation ∂/∂v_t = H_r·C (Pose3: p ← p + C v), rotation ∂/∂θ = H_ψ·C
(C ← C Exp(θ), ψ = C θ), the G(k) columns = H_e on the carried axes.
"""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.updates import gnss_rows as ekf_gnss_rows
from vnav_graph.estimators.graph.model import interval_factors as gf
from vnav_graph.estimators.graph.model.dense_increments import dense_preintegration
from vnav_graph.geo.earth import radii_scalar
from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.nav.rotations import quat_to_dcm, rpy_quat, so3_exp
from vnav_graph.sensors.gnss_model import (
    GM_AXES,
    antenna_arrays,
    antenna_position,
    antenna_velocity,
)

LEVER = np.array([0.6, -0.25, -1.1])



def _attitude(rng):
    return quat_to_dcm(rpy_quat(*rng.normal(0.0, 0.2, 2), rng.uniform(-3.0, 3.0)))


def test_antenna_jacobians_match_finite_differences():
    """C̃ = (I + [ψ×]) C to first order, i.e. C̃ = Exp(ψ) C; ω = ω̃ − b_g."""
    rng = np.random.default_rng(5)
    c = _attitude(rng)
    w = rng.normal(0.0, 0.3, 3)
    d, h_att = antenna_position(c, LEVER)
    u, hv_att, hv_bg = antenna_velocity(c, LEVER, w)
    np.testing.assert_allclose(d, c @ LEVER, rtol=1e-15)
    np.testing.assert_allclose(u, c @ np.cross(w, LEVER), rtol=1e-15)
    eps = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = eps
        cp, cm = so3_exp(e) @ c, so3_exp(-e) @ c
        fd_p = (antenna_position(cp, LEVER)[0] - antenna_position(cm, LEVER)[0]) / (2 * eps)
        fd_v = (antenna_velocity(cp, LEVER, w)[0] - antenna_velocity(cm, LEVER, w)[0]) / (2 * eps)
        # b_g enters as ω = ω̃ − b_g: ∂/∂δb_g (estimated minus true) is −∂/∂ω̃... of the true
        # rate, i.e. +∂u/∂b_g of the estimate: u(ω̃ − b̂_g) with b̂_g = b_g + δb_g
        fd_b = (antenna_velocity(c, LEVER, w - e)[0] - antenna_velocity(c, LEVER, w + e)[0]) \
            / (2 * eps)
        # central differences of smooth functions: error O(ε²) ≈ 1e-12, round-off ≈ 1e-10
        np.testing.assert_allclose(h_att[:, j], fd_p, atol=1e-9)
        np.testing.assert_allclose(hv_att[:, j], fd_v, atol=1e-9)
        np.testing.assert_allclose(hv_bg[:, j], fd_b, atol=1e-9)


def test_batch_forms_map_the_compiled_ones_exactly():
    rng = np.random.default_rng(8)
    c = np.array([_attitude(rng) for _ in range(4)])
    w = rng.normal(0.0, 0.3, (4, 3))
    d, h, u, hv = antenna_arrays(c, LEVER, w)
    d0, h0, u0, _ = antenna_arrays(c, LEVER, np.empty((0, 3)))  # position only
    np.testing.assert_array_equal(d0, d)
    np.testing.assert_array_equal(h0, h)
    assert u0.shape == (0, 3)
    for i in range(4):
        d1, h1 = antenna_position(c[i], LEVER)
        u1, hv1, _ = antenna_velocity(c[i], LEVER, w[i])
        # the same compiled function at each epoch: the same bits
        np.testing.assert_array_equal(d[i], d1)
        np.testing.assert_array_equal(h[i], h1)
        np.testing.assert_array_equal(u[i], u1)
        np.testing.assert_array_equal(hv[i], hv1)


def _graph_at(lla, c, ge, dim, rng):
    """A 3-keyframe graph state with keyframe 1 at ``lla`` (the tangent origin), attitude c
    and GNSS error ``ge`` on the axes of ``dim``; IMU samples of a random motion."""
    t = np.arange(0.0, 2.0 + 1e-9, 0.01)
    gyro = 0.2 * rng.normal(size=(t.size, 3))
    accel = np.array([0.3, -0.2, -9.8]) + rng.normal(size=(t.size, 3))
    kf = gf.keyframe_indices(t, 1.0)
    dense = dense_preintegration(t, gyro, accel, kf)
    nk = kf.size
    rot = np.array([so3_exp(rng.normal(0.0, 0.3, 3)) for _ in range(nk)])
    rot[1] = c
    pos = rng.normal(0.0, 5.0, (nk, 3))
    pos[1] = 0.0
    g = rng.normal(0.0, 2.0, (nk, dim))
    g[1] = ge[list(GM_AXES[dim])]
    st = gf.KeyframeStates(rot, pos, rng.normal(size=(nk, 3)), np.zeros((nk, 3)),
                           np.zeros(nk), np.zeros(nk), np.zeros(nk),
                           np.tile([0.0, 0.0, 9.8], (nk, 1)), g[:, 0] if dim == 1 else g)
    return dense, st


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_filter_and_graph_give_the_same_residual_and_jacobian(dim):
    rng = np.random.default_rng(11 + dim)
    lla = np.array([np.radians(48.1), np.radians(11.6), 530.0])
    c = _attitude(rng)
    ge = np.zeros(3)
    ge[list(GM_AXES[dim])] = rng.normal(0.0, 2.0, dim)
    fix_ned = rng.normal(0.0, 3.0, 3)
    fix_lla = ned_to_lla(fix_ned[None, :], lla)[0]
    sd = np.array([1.2, 1.2, 2.0])
    # the filter's row at its nominal state
    rn, re = radii_scalar(lla[0])
    y, hm, _, mm = ekf_gnss_rows(lla, np.zeros(3), c, rn, re, ge, LEVER, fix_lla, sd,
                                 np.zeros(3), np.full(3, 0.1), False, True, np.zeros(3),
                                 np.zeros(3))
    assert mm == 3
    # the graph's factor on keyframe 1's epoch, tangent frame at lla
    dense, st = _graph_at(lla, c, ge, dim, rng)
    t_g = np.array([dense.t_kf[1]])
    rows = gf.gnss_rows(dense, st, t_g, lla_to_ned(fix_lla[None, :], lla), sd[None, :], None,
                        None, LEVER, k=np.array([1]))
    r_g = rows.r * sd
    jac = rows.jac * sd[:, None]
    # the filter converts the fix with the radii (first order in the offset): |Δ| ≈ |z|²/R
    # ≈ 1e-6 m for a 3 m offset
    np.testing.assert_allclose(r_g, y[:3], rtol=0, atol=1e-5)
    np.testing.assert_allclose(jac[:, 3:6], hm[:3, km.IPOS:km.IPOS + 3] @ c, atol=1e-12)
    np.testing.assert_allclose(jac[:, 0:3], hm[:3, km.IATT:km.IATT + 3] @ c, atol=1e-12)
    c0, c1 = gf.gm_cols(dim)
    cols = [km.IGE + a for a in GM_AXES[dim]]
    np.testing.assert_allclose(jac[:, c0], hm[:3, cols], atol=1e-12)
    assert np.all(jac[:, c1] == 0.0)  # α = 0: keyframe k+1's error does not enter
    # and both use the shared model's lever-arm column (not a zero one): −[(C l)×]
    np.testing.assert_allclose(hm[:3, km.IATT:km.IATT + 3], antenna_position(c, LEVER)[1],
                               rtol=0, atol=0)


def test_magnetometer_filter_row_and_graph_factor_agree():
    """The same shared model for the magnetometer: the graph's heading factor on X(k), H(0)
    against the EKF's row at the same attitude, hard iron and sample."""
    import gtsam
    from gtsam.symbol_shorthand import H, X

    from vnav_graph.estimators.ekf.heading import new_state
    from vnav_graph.estimators.ekf.updates import mag_rows
    from vnav_graph.estimators.graph.model.builtin_sensors import mag_heading_factor

    rng = np.random.default_rng(21)
    c = _attitude(rng)
    bias = rng.normal(0.0, 2.0, 3)
    z = c.T @ np.array([21.0, 1.5, 42.0]) + bias + rng.normal(0.0, 0.5, 3)
    decl, sd = 0.05, 0.02
    par = np.zeros(km.NPAR)
    par[km.PMB:km.PMB + 3] = bias
    y, hm, _, mm = mag_rows(z, par, c, decl, 0.5, 1e-4, True, np.eye(km.NX) * 1e-4,
                            new_state())
    assert mm == 1
    f = mag_heading_factor(3, z, decl, sd, 100.0)  # Huber at 100 σ: no re-weighting here
    vals = gtsam.Values()
    vals.insert(X(3), gtsam.Pose3(gtsam.Rot3(c), np.zeros(3)))
    vals.insert(H(0), bias)
    a = f.linearize(vals).jacobian()[0] * sd  # whitened [∂/∂X(3) | ∂/∂H(0)] times σ
    np.testing.assert_allclose(f.unwhitenedError(vals), [y[0]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a[0, 0:3], hm[0, km.IATT:km.IATT + 3] @ c, atol=1e-12)
    assert np.all(a[0, 3:6] == 0.0)
    np.testing.assert_allclose(a[0, 6:9], hm[0, km.IMB:km.IMB + 3], atol=1e-12)
    # and it is the derivative: the rotation column against central differences of the error
    eps = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = eps
        vp, vm = gtsam.Values(), gtsam.Values()
        for v, s in ((vp, 1.0), (vm, -1.0)):
            v.insert(X(3), gtsam.Pose3(gtsam.Rot3(c @ so3_exp(s * e)), np.zeros(3)))
            v.insert(H(0), bias)
        fd = (f.unwhitenedError(vp)[0] - f.unwhitenedError(vm)[0]) / (2 * eps)
        # central difference, O(ε²) truncation, ~1e-10 round-off over 2ε
        assert a[0, j] == pytest.approx(fd, abs=1e-7)


def test_the_flat_config_keys_set_one_model_in_both_families(tmp_path):
    """``--config`` keys: the height-only ``gnss_gm_sd_v`` / ``gnss_gm_tau_s`` keep their
    meaning, ``gnss_gm_sd_h`` adds north and east; both families read the same fields."""
    from vnav_graph.estimators.configfile import load_configs
    from vnav_graph.sensors.gnss_model import GnssGM

    p = tmp_path / "c.toml"
    p.write_text("[ekf-rts]\ngnss_gm_sd_v = 3.0\ngnss_gm_tau_s = 120.0\n"
                 "[graph-batch]\ngnss_gm_sd_v = 3.0\ngnss_gm_tau_s = 120.0\n"
                 "[graph-isam2]\ngnss_gm_sd_h = 2.0\ngnss_gm_sd_v = 3.0\ngnss_gm_tau_s = 60.0\n"
                 "[ekf]\ngnss_gm_sd_h = 2.0\n")
    c = load_configs(p)
    assert c["ekf-rts"].gnss_gm == c["graph-batch"].gnss_gm == GnssGM(0.0, 3.0, 120.0)
    assert c["graph-batch"].gnss_gm.axes == (2,)
    assert c["graph-isam2"].gnss_gm == GnssGM(2.0, 3.0, 60.0)
    assert c["ekf"].gnss_gm.axes == (0, 1) and c["ekf"].gnss_gm.tau_s == 300.0
