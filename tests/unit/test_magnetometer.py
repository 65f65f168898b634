"""The shared magnetometer heading model: closed forms and finite-difference Jacobians."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.nav.rotations import skew3
from vnav_graph.sensors.magnetometer import heading_sd, mag_heading_row, wrap_pi

M_N = np.array([20.0, 1.5, 43.0])  # NED [µT], dip 65°, declination 4.3°
DECL = np.arctan2(M_N[1], M_N[0])


def _c_nb(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def _expm(w: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(w).as_matrix()


@pytest.mark.parametrize("att", [(0.0, 0.0, 0.3), (0.2, -0.3, 2.9), (-0.5, 0.4, -1.7)])
def test_true_attitude_and_bias_give_the_declination(att: tuple[float, float, float]) -> None:
    c = _c_nb(*att)
    b = np.array([4.0, -3.0, 2.0])
    z = c.T @ M_N + b
    r, h_psi, h_b, hor = mag_heading_row(z, b, c, DECL)
    assert r == pytest.approx(0.0, abs=1e-12)
    assert hor == pytest.approx(np.hypot(M_N[0], M_N[1]), rel=1e-12)
    assert mag_heading_row(z, b, c, 0.0)[0] == pytest.approx(DECL, abs=1e-12)  # the azimuth
    # closed form of the tilt and yaw components (module docstring)
    h2 = M_N[0] ** 2 + M_N[1] ** 2
    np.testing.assert_allclose(h_psi, [-M_N[0] * M_N[2] / h2, -M_N[1] * M_N[2] / h2, 1.0],
                               atol=1e-12)


@pytest.mark.parametrize("att", [(0.1, 0.05, 0.7), (-0.3, 0.2, -2.5)])
def test_ekf_jacobians_match_finite_differences(att: tuple[float, float, float]) -> None:
    rng = np.random.default_rng(3)
    c = _c_nb(*att)
    b_true = np.array([4.0, -3.0, 2.0])
    z = c.T @ M_N + b_true + rng.normal(scale=0.3, size=3)
    b = b_true + rng.normal(scale=1.0, size=3)
    r0, h_psi, h_b, _ = mag_heading_row(z, b, c, DECL)
    eps = 1e-6
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        cp = (np.eye(3) + skew3(d)) @ c  # C̃ = (I + [ψ×]) C (first order is all we need)
        rp = mag_heading_row(z, b, cp, DECL)[0]
        cm = (np.eye(3) - skew3(d)) @ c
        rm = mag_heading_row(z, b, cm, DECL)[0]
        assert (rp - rm) / (2 * eps) == pytest.approx(h_psi[i], rel=1e-5, abs=1e-8)
        bp = mag_heading_row(z, b + d, c, DECL)[0]
        bm = mag_heading_row(z, b - d, c, DECL)[0]
        assert (bp - bm) / (2 * eps) == pytest.approx(h_b[i], rel=1e-5, abs=1e-9)
    # the closed form: azimuth atan2(m_E, m_N) of m = C (z − b), bias row −g C with
    # g = (−m_E, m_N, 0)/H²
    m = c @ (z - b)
    assert wrap_pi(np.arctan2(m[1], m[0]) - DECL) == pytest.approx(r0, abs=1e-12)
    g = np.array([-m[1], m[0], 0.0]) / (m[0] ** 2 + m[1] ** 2)
    np.testing.assert_allclose(-g @ c, h_b, atol=1e-12)


def test_graph_chain_rule_matches_finite_differences() -> None:
    """The graph's retraction R Exp(ω): ∂a/∂ω = (∂a/∂ψ) R, the row's n-frame column times R."""
    c = _c_nb(0.2, -0.1, 1.2)
    z = c.T @ M_N + np.array([1.0, 2.0, -1.0])
    b = np.array([0.5, 1.5, -0.5])
    _, h_psi, _, _ = mag_heading_row(z, b, c, 0.0)
    jac = h_psi @ c
    eps = 1e-6
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        ap = mag_heading_row(z, b, c @ _expm(d), 0.0)[0]
        am = mag_heading_row(z, b, c @ _expm(-d), 0.0)[0]
        assert (ap - am) / (2 * eps) == pytest.approx(jac[i], rel=1e-6, abs=1e-9)


def test_heading_sd_and_wrap() -> None:
    assert heading_sd(0.2, 20.0, 0.0) == pytest.approx(0.01)
    assert heading_sd(0.0, 20.0, 0.03) == pytest.approx(0.03)
    assert wrap_pi(np.pi + 0.1) == pytest.approx(-np.pi + 0.1)
    assert wrap_pi(-np.pi - 0.1) == pytest.approx(np.pi - 0.1)



def test_magstream_validates() -> None:
    from vnav_graph.types.streams import MagStream

    m = MagStream(np.arange(3.0), np.ones((3, 3)) * 20.0, 0.5)
    assert len(m) == 3 and m.sd_ut == 0.5
    with pytest.raises(ValueError, match="mag.field_b"):
        MagStream(np.arange(3.0), np.ones((3, 3)) * 3000.0)  # milligauss passed as µT
    with pytest.raises(ValueError, match=r"mag.field_b: expected shape"):
        MagStream(np.arange(3.0), np.ones((3, 2)))
    with pytest.raises(ValueError, match="sd_ut"):
        MagStream(np.arange(3.0), np.ones((3, 3)), 0.0)


def test_hard_iron_note_is_the_chi2_3_gate() -> None:
    """Closed form: χ²₃ at 0.999 is 16.27, i.e. 4.03σ along one axis."""
    from vnav_graph.estimators.checks import hard_iron_note

    def info(b):
        return {"extra_variables": {"h0": {"est": list(b), "sd": [1.0, 1.0, 1.0]}}}

    assert hard_iron_note(info([4.0 * 3.0, 0.0, 0.0]), 3.0) == ""  # χ² 16.0
    note = hard_iron_note(info([4.1 * 3.0, 0.0, 0.0]), 3.0)  # χ² 16.8
    assert note.startswith("magnetometer not used") and "4.1σ" in note
    assert hard_iron_note(info([0.0, 2.4 * 3.0, 3.3 * 3.0]), 3.0) != ""  # χ² 16.65
    assert hard_iron_note({"extra_variables": {}}, 3.0) == ""
    assert hard_iron_note({}, 3.0) == ""
