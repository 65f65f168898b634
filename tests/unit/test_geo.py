"""Earth model and standard atmosphere against published values and pymap3d."""

import numpy as np
import pytest

from vnav_graph.geo import atmosphere as atm
from vnav_graph.geo import earth
from vnav_graph.geo.frames import lla_to_ned, ned_to_lla, quat_to_rph, rph_to_quat, slerp_quat

# ICAO/ISO 2533 standard atmosphere table (pressure in Pa at geopotential altitude in m);
# the tables print 5-6 significant digits, hence the relative tolerance 2e-5.
ISA_TABLE = [(0.0, 101325.0), (1000.0, 89874.6), (2000.0, 79495.2), (5000.0, 54019.9),
             (8000.0, 35599.8), (11000.0, 22632.1), (15000.0, 12044.6), (20000.0, 5474.89)]


@pytest.mark.parametrize("h, p", ISA_TABLE)
def test_isa_pressure_matches_table(h, p):
    assert atm.isa_pressure(h) == pytest.approx(p, rel=2e-5)
    assert atm.isa_altitude(p) == pytest.approx(h, abs=0.3)  # 2e-5 of p ≈ 0.2 m of altitude


def test_isa_round_trip_with_nonstandard_day():
    h = np.linspace(-500, 19500, 101)
    for dT, p0 in [(0.0, atm.P0), (15.0, 100800.0), (-20.0, 102300.0)]:
        back = atm.isa_altitude(atm.isa_pressure(h, dT, p0), dT, p0)
        np.testing.assert_allclose(back, h, atol=1e-6)  # exact inverse up to round-off


def test_nonstandard_atmosphere_gives_scale_and_bias():
    # warm day: the standard-law altimeter under-reads by dT/(T0+dT) ≈ 0.35 %/K
    scale, _ = atm.baro_error_from_atmosphere(500.0, dT=1.0)
    assert scale == pytest.approx(-1.0 / (atm.T0 + 1.0), rel=1e-3)
    # sea-level pressure 1 hPa low: reads high by RT/(gp) per Pa ≈ 8.3 m/hPa at sea level
    _, bias = atm.baro_error_from_atmosphere(0.0, dT=0.0, p0=atm.P0 - 100.0)
    assert bias == pytest.approx(8.32, abs=0.02)


def test_out_of_range_inputs_are_rejected():
    with pytest.raises(ValueError):
        atm.isa_pressure(25000.0)
    with pytest.raises(ValueError):
        atm.isa_altitude(-1.0)


def test_normal_gravity_reference_values():
    # TR8350.2: γ_e = 9.7803253359, γ_p = 9.8321849378; free-air gradient ≈ −3.086e-6 s^-2
    assert earth.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert earth.gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    grad = (earth.gravity(0.8, 1000.0) - earth.gravity(0.8, 0.0)) / 1000.0
    assert grad == pytest.approx(-3.086e-6, rel=3e-3)


def test_radii_and_gravity_compiled_for_scalars_equal_the_array_forms():
    rn, re = earth.radii(0.0)
    assert rn == pytest.approx(6335439.327, abs=1e-3)  # a(1−e²) at the equator
    assert re == pytest.approx(6378137.0, abs=1e-6)
    for lat in (-1.2, 0.0, 0.3, 1.5):
        assert earth.radii_scalar(lat) == pytest.approx(tuple(earth.radii(lat)), rel=1e-15)
        assert earth.gravity_scalar(lat, 1234.0) == pytest.approx(
            float(earth.gravity(lat, 1234.0)), rel=1e-15)


def test_lla_ned_round_trip_and_closed_forms(rng):
    origin = np.array([np.radians(47.2), np.radians(11.4), 580.0])
    ned = rng.normal(0, 5000, (50, 3))
    lla = ned_to_lla(ned, origin)
    np.testing.assert_allclose(lla_to_ned(lla, origin), ned, atol=1e-6)
    # closed forms from the radii of curvature (independent of pymap3d, which the module
    # wraps): 1 km north → Δlat = n/(R_N + h) and the tangent plane lies n²/(2(R_N + h))
    # above the ellipsoid; 1 km east → Δlon = e/((R_E + h) cos lat); straight up → height.
    rn, re = earth.radii(origin[0])
    north = ned_to_lla([[1000.0, 0.0, 0.0]], origin)[0]
    assert north[0] - origin[0] == pytest.approx(1000.0 / (rn + origin[2]), rel=1e-5)
    assert north[2] - origin[2] == pytest.approx(1000.0**2 / (2 * (rn + origin[2])), rel=1e-3)
    east = ned_to_lla([[0.0, 1000.0, 0.0]], origin)[0]
    assert east[1] - origin[1] == pytest.approx(
        1000.0 / ((re + origin[2]) * np.cos(origin[0])), rel=1e-5)
    up = ned_to_lla([[0.0, 0.0, -100.0]], origin)[0]
    np.testing.assert_allclose(up, origin + [0.0, 0.0, 100.0], atol=1e-9)


def test_euler_quaternion_round_trip(rng):
    rph = np.column_stack([rng.uniform(-3, 3, 20), rng.uniform(-1.5, 1.5, 20),
                           rng.uniform(-3, 3, 20)])
    np.testing.assert_allclose(quat_to_rph(rph_to_quat(rph)), rph, atol=1e-12)


def test_slerp_on_knots_and_between(rng):
    # knots: the normalised input quaternion (no Slerp built); between knots: the closed-form
    # slerp q0 (q0⁻¹ q1)^a of a rotation about one axis
    t = np.arange(6.0)
    ang = np.array([0.0, 0.3, 0.5, 0.4, -0.2, 0.1])
    q = np.column_stack([np.cos(ang / 2), np.zeros(6), np.zeros(6), np.sin(ang / 2)])
    q[2] *= -3.0  # unnormalised and of the other sign: same rotation
    tq = np.array([0.0, 0.25, 2.0, 3.5, 5.0])
    out = slerp_quat(t, q, tq)
    a = np.array([0.0, 0.25 * 0.3, 0.5, 0.5 * (0.4 - 0.2), 0.1])
    np.testing.assert_allclose(out, np.column_stack([np.cos(a / 2), np.zeros(5), np.zeros(5),
                                                     np.sin(a / 2)]), atol=1e-12)
    np.testing.assert_allclose(slerp_quat(t, q, 3.5), out[3], atol=1e-15)
    only_knots = slerp_quat(t, q, t)
    np.testing.assert_allclose(np.linalg.norm(only_knots, axis=1), 1.0, atol=1e-15)
    assert np.all(only_knots[:, 0] >= 0)


def test_slerp_matches_scipy_slerp_on_random_rotations(rng):
    # slerp_quat works on the bracketing knots only; scipy's Slerp built on all knots is the
    # reference (same rotation, so q or -q)
    from scipy.spatial.transform import Rotation, Slerp

    t = np.cumsum(rng.uniform(0.05, 1.0, 300))
    rot = Rotation.random(300, random_state=rng)
    tq = np.sort(rng.uniform(t[0], t[-1], 2000))
    out = slerp_quat(t, rot.as_quat(scalar_first=True), tq)
    ref = Slerp(t, rot)(tq).as_quat(scalar_first=True)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", out, ref)), 1.0, atol=1e-12)
    assert np.all(out[:, 0] >= 0)
