"""Reference ``gtsam.CustomFactor``s for the graph's terms on keyframe variables.

The companion of ``test_reference_factors.py`` (the terms through the keyframe interpolant;
its docstring lists every term and the conventions). Here, each written from the physics in
the module docstrings, on GTSAM's variable types, never calling the product's models:

5. the magnetometer heading (``graph.model.builtin_sensors.mag_heading_factor``: a CustomFactor
   whose error is the shared row ``sensors.magnetometer.mag_heading_row``), keys X(k), H(0):
   e = wrap(atan2(m_E, m_N) − D), m = R_k (z − b_m); Jacobians from ``Rot3.rotate``'s and
   the gradient of atan2. The product's factor is robust (Huber), so the comparison is of
   the unwhitened error and Jacobian blocks (``unwhitenedError`` with a
   ``gtsam.JacobianVector``), which the loss does not touch;
6. the Gauss-Markov links ``cpp_factors.gm_link`` (baro bias C(k), GNSS height error) and
   ``gnss_gm_factor`` (G(k) of dimension 1–3): e = x_{k+1} − φ x_k, φ = e^{−Δt/τ},
   σ_w = σ√(1 − φ²) per axis;
7. the IMU biases' link ``cpp_factors.bias_link`` on B(k), B(k+1) (ConstantBias, tangent
   (accel, gyro)) and, with accelerometer scale factors, the scale variables of intervals k
   and k+1: B holds b_a + diag(ā_k) k_a, so
   e_a = B_a(k+1) − diag(ā_{k+1}) k_a' − φ_a (B_a(k) − diag(ā_k) k_a),
   e_g = B_g(k+1) − φ_g B_g(k), φ = e^{−Δt/τ}, σ_w² = σ²(1 − φ²) + rw²·Δt per component.

These product factors are GTSAM linear factors whose coefficients the product computes, so
their errors and whitened Jacobians must equal the reference's at any values (exact).
"""

from __future__ import annotations

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import A, B, G, H, X

from vnav_graph.config import ImuSpec
from vnav_graph.estimators.graph import check_jacobians
from vnav_graph.estimators.graph.model.accel_scale import AccelScale
from vnav_graph.estimators.graph.model.builtin_sensors import mag_heading_factor
from vnav_graph.estimators.graph.model.cpp_factors import bias_link, gm_link, gnss_gm_factor
from vnav_graph.sensors.gnss_model import GnssGM

SEEDS = (11, 12, 13)
# measured: heading errors and Jacobians agree to ≤ 2.3e-16, the links' costs and whitened
# Jacobians to ≤ 6e-15 relative (round-off); a wrong input moves them by 0.3 % … 4×
TOL = 1e-9


def _assert_own_jacobians(factor, values: gtsam.Values) -> None:
    chk = check_jacobians(factor, values, eps=1e-6, tol=1e-6)
    assert chk.ok, str(chk)


def _raw(factor, values: gtsam.Values) -> tuple[np.ndarray, list[np.ndarray]]:
    """Unwhitened error and Jacobian blocks of a noise-model factor."""
    jac = gtsam.JacobianVector()
    for _ in factor.keys():
        jac.append(np.zeros((0, 0)))
    e = np.asarray(factor.unwhitenedError(values, jac))
    return e, [np.asarray(j) for j in jac]


# --- magnetometer heading ------------------------------------------------------------------

def heading_reference(k: int, z_b: np.ndarray, decl: float, sd: float):
    """Reference heading factor on X(k), H(0) (term 5)."""

    def error_func(this: gtsam.CustomFactor, v: gtsam.Values, jac: list | None) -> np.ndarray:
        kx, kh = this.keys()
        h_r = np.zeros((3, 6))
        rk = v.atPose3(kx).rotation(h_r)
        h_rot, h_pt = np.zeros((3, 3)), np.zeros((3, 3))
        m = rk.rotate(z_b - v.atVector(kh), h_rot, h_pt)
        e = (np.arctan2(m[1], m[0]) - decl + np.pi) % (2 * np.pi) - np.pi
        if jac is not None:
            grad = np.array([[-m[1], m[0], 0.0]]) / (m[0] ** 2 + m[1] ** 2)
            jac[0] = grad @ h_rot @ h_r
            jac[1] = -grad @ h_pt
        return np.array([e])

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, sd), [X(k), H(0)],
                              error_func)


def _heading_case(seed: int, decl_sign: float = 1.0):
    rng = np.random.default_rng(seed)
    k, decl, sd = 2, float(rng.uniform(-0.3, 0.3)), 0.05
    z_b = np.array([20.0, -4.0, 43.0]) + 5.0 * rng.normal(size=3)
    values = gtsam.Values()
    values.insert(X(k), gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3)), rng.normal(size=3)))
    values.insert(H(0), 3.0 * rng.normal(size=3))
    prod = mag_heading_factor(k, z_b, decl_sign * decl, sd, 3.0)
    return heading_reference(k, z_b, decl, sd), prod, values


def _compare_heading(ref, prod, values: gtsam.Values) -> None:
    e_r, j_r = _raw(ref, values)
    e_p, j_p = _raw(prod, values)
    np.testing.assert_allclose(e_p, e_r, rtol=0, atol=TOL * np.pi, err_msg="error")
    for a, b in zip(j_p, j_r, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=TOL * max(1.0, np.abs(b).max()),
                                   err_msg="Jacobian")


@pytest.mark.parametrize("seed", SEEDS)
def test_heading_factor_equals_the_reference(seed):
    ref, prod, values = _heading_case(seed)
    _assert_own_jacobians(ref, values)
    _compare_heading(ref, prod, values)


# --- Gauss-Markov links --------------------------------------------------------------------

def gm_reference(key0: int, key1: int, dt: float, tau: float, sd: np.ndarray):
    """Reference Gauss-Markov link x1 − φ x0 (term 6), σ_w = σ √(1 − φ²) per axis."""
    phi = np.exp(-dt / tau)
    n = sd.size

    def error_func(this: gtsam.CustomFactor, v: gtsam.Values, jac: list | None) -> np.ndarray:
        k0, k1 = this.keys()
        if jac is not None:
            jac[0], jac[1] = -phi * np.eye(n), np.eye(n)
        return v.atVector(k1) - phi * v.atVector(k0)

    return gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(sd * np.sqrt(1 - phi**2)),
                              [key0, key1], error_func)


def _compare_linear(prod, ref, values: gtsam.Values) -> None:
    """Equal cost and whitened linearisation (A, b) at ``values``."""
    assert prod.error(values) == pytest.approx(ref.error(values), rel=TOL)
    a_p, b_p = prod.linearize(values).jacobian()
    a_r, b_r = ref.linearize(values).jacobian()
    np.testing.assert_allclose(a_p, a_r, rtol=0, atol=TOL * np.abs(a_r).max())
    np.testing.assert_allclose(b_p, b_r, rtol=0, atol=TOL * max(1.0, np.abs(b_r).max()))


def _gm_case(dim: int, sd_prod=None):
    rng = np.random.default_rng(dim)
    dt, tau = 0.7, 45.0
    gm = GnssGM(sd_h=1.3 if dim > 1 else 0.0, sd_v=2.1 if dim != 2 else 0.0, tau_s=tau)
    assert gm.dim == dim
    values = gtsam.Values()
    values.insert(G(3), rng.normal(size=dim))
    values.insert(G(4), rng.normal(size=dim))
    if sd_prod is None:
        prod = gnss_gm_factor(3, dt, gm)
    else:  # the scalar link (the baro bias chain's) with the σ given
        prod = gm_link(G(3), G(4), dt, tau, sd_prod)
    return prod, gm_reference(G(3), G(4), dt, tau, gm.sd), values


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_gauss_markov_links_equal_the_reference(dim):
    """``gnss_gm_factor`` of each dimension and ``gm_link`` (the scalar link of the baro
    bias and the height error) against x1 − φ x0 with σ_w = σ√(1 − φ²)."""
    prod, ref, values = _gm_case(dim)
    _assert_own_jacobians(ref, values)
    _compare_linear(prod, ref, values)
    if dim == 1:
        _compare_linear(*_gm_case(1, sd_prod=2.1)[:2], values)


# --- IMU bias link -------------------------------------------------------------------------

SPEC = ImuSpec(accel_bias_rw=2e-4, gyro_bias_rw=3e-6, accel_bias_tau=900.0,
               gyro_bias_tau=1800.0)


def bias_reference(k: int, dt: float, spec: ImuSpec, f_mean: np.ndarray | None,
                   a_keys: tuple[int, int] | None):
    """Reference IMU bias link (term 7) on B(k), B(k+1) and the scale keys ``a_keys``
    (one key when both intervals share it); ``f_mean`` (K, 3): the interval mean forces."""
    phi_a, phi_g = np.exp(-dt / spec.accel_bias_tau), np.exp(-dt / spec.gyro_bias_tau)
    var_a = spec.accel_bias_sd**2 * (1 - phi_a**2) + spec.accel_bias_rw**2 * dt
    var_g = spec.gyro_bias_sd**2 * (1 - phi_g**2) + spec.gyro_bias_rw**2 * dt
    sd = np.sqrt(np.r_[[var_a] * 3, [var_g] * 3])
    keys = [B(k), B(k + 1)]
    if a_keys is not None:
        keys += [a_keys[0]] if a_keys[0] == a_keys[1] else list(a_keys)
    d0 = -np.diag(np.r_[[phi_a] * 3, [phi_g] * 3])

    def error_func(this: gtsam.CustomFactor, v: gtsam.Values, jac: list | None) -> np.ndarray:
        b0, b1 = v.atConstantBias(keys[0]), v.atConstantBias(keys[1])
        ea = b1.accelerometer() - phi_a * b0.accelerometer()
        blocks = [d0, np.eye(6)]
        if a_keys is not None:
            f0, f1 = f_mean[k], f_mean[k + 1]
            k0, k1 = v.atVector(a_keys[0]), v.atVector(a_keys[1])
            ea = ea - f1 * k1 + phi_a * f0 * k0
            h0, h1 = np.zeros((6, 3)), np.zeros((6, 3))
            h0[0:3], h1[0:3] = phi_a * np.diag(f0), -np.diag(f1)
            blocks += [h0 + h1] if a_keys[0] == a_keys[1] else [h0, h1]
        if jac is not None:
            for i, blk in enumerate(blocks):
                jac[i] = blk
        return np.r_[ea, b1.gyroscope() - phi_g * b0.gyroscope()]

    return gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(sd), keys, error_func)


def _bias_case(variant: str, f_shift: int = 0):
    rng = np.random.default_rng(7)
    k, dt = 2, 0.8
    f_mean = np.array([0.3, -0.2, -9.8]) + rng.normal(size=(5, 3))
    a_keys = {"no scale": None, "one scale": (A(0), A(0)), "two scales": (A(0), A(1))}[variant]
    P = SimpleNamespace(imu_spec=SPEC, ka=None if a_keys is None else
                        AccelScale(1e-3, np.roll(f_mean, f_shift, axis=0)))
    prod = bias_link(P, k, dt, a_keys)
    values = gtsam.Values()
    for j in (k, k + 1):
        values.insert(B(j), gtsam.imuBias.ConstantBias(0.05 * rng.normal(size=3),
                                                       1e-3 * rng.normal(size=3)))
    for key in set(a_keys or ()):
        values.insert(key, 2e-3 * rng.normal(size=3))
    return prod, bias_reference(k, dt, SPEC, f_mean, a_keys), values


@pytest.mark.parametrize("variant", ["no scale", "one scale", "two scales"])
def test_bias_link_equals_the_reference(variant):
    prod, ref, values = _bias_case(variant)
    _assert_own_jacobians(ref, values)
    if variant != "two scales":
        _compare_linear(prod, ref, values)
    else:  # four keys: Hessian pieces with 1e-9 added information (``information_factor``)
        dx = np.concatenate([values.atConstantBias(B(2)).vector(),
                             values.atConstantBias(B(3)).vector(),
                             values.atVector(A(0)), values.atVector(A(1))])
        assert abs(prod.error(values) - ref.error(values)) <= 0.5e-9 * dx @ dx \
            + TOL * ref.error(values)


# --- the checks can fail -------------------------------------------------------------------

WRONG = ["heading declination sign", "gm link variance for sigma",
         "bias link forces of the next interval"]


@pytest.mark.parametrize("case", WRONG)
def test_the_comparison_detects_wrong_inputs(case):
    """A wrong product-side input fails the comparison (the checks can fail)."""
    with pytest.raises(AssertionError):
        if case.startswith("heading"):
            _compare_heading(*_heading_case(SEEDS[0], decl_sign=-1.0))
        elif case.startswith("gm"):
            prod, ref, values = _gm_case(1, sd_prod=2.1**2)
            _compare_linear(prod, ref, values)
        else:
            _compare_linear(*_bias_case("one scale", f_shift=-1))
