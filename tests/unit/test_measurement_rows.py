"""The filter's measurement rows (``ekf.updates``) against finite differences of their own
innovation under the filter's error convention, and the baro row against the shared sensor
model the graph's factor evaluates (``sensors.baro.baro_arrays``).

For a row function y(x̃) with Jacobian H: removing an error δx from the nominal state
(``model.apply_correction``, x' = x̃ ⊖ δx) must change the innovation by H δx to first
order, column by column."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.heading import new_state
from vnav_graph.estimators.ekf.updates import baro_rows, gnss_rows, mag_rows
from vnav_graph.geo.earth import radii_scalar
from vnav_graph.nav.rotations import quat_to_dcm, rpy_quat
from vnav_graph.sensors.baro import baro_arrays


def _state(rng):
    lla = np.array([np.radians(47.3), np.radians(11.4), 612.0])
    v = rng.normal(0.0, 8.0, 3)
    q = rpy_quat(*rng.normal(0.0, 0.2, 2), rng.uniform(-3.0, 3.0))
    par = np.zeros(km.NPAR)
    par[km.PSC], par[km.PTD], par[km.PBB] = 0.012, 0.21, 3.4
    par[km.PBG:km.PBG + 3] = rng.normal(0.0, 1e-3, 3)
    par[km.PMB:km.PMB + 3] = rng.normal(0.0, 2.0, 3)
    par[km.PGE:km.PGE + 3] = rng.normal(0.0, 2.0, 3)
    return lla, v, q, par


def _corrected(state, j, eps):
    lla, v, q, par = (a.copy() for a in state)
    dx = np.zeros(km.NX)
    dx[j] = eps
    km.apply_correction(lla, v, q, par, dx)
    return lla, v, q, par


def _fd_columns(fn, state, cols, eps):
    """(y(x̃) − y(x̃ ⊖ ε e_j)) / ε for each column j."""
    y0 = fn(state)
    return {j: (y0 - fn(_corrected(state, j, eps))) / eps for j in cols}


def test_baro_row_is_the_shared_model_and_its_derivative():
    rng = np.random.default_rng(4)
    state = _state(rng)
    h0, z, sd = 580.0, 615.0, 0.4
    lla, v, q, par = state
    y, hm, r, mm = baro_rows(lla, v, par, h0, z, sd)
    assert mm == 1 and r[0] == sd * sd
    # the innovation is the shared model's prediction minus the sample
    pred, jb = baro_arrays(lla[2], -v[2], par[km.PSC], par[km.PTD], par[km.PBB], h0)
    assert y[0] == pytest.approx(pred - z, rel=0, abs=1e-12)
    assert hm[0, km.IPOS + 2] == pytest.approx(-jb[0])  # down error, height up
    assert hm[0, km.ISC] == pytest.approx(jb[2]) and hm[0, km.IBB] == pytest.approx(jb[4])

    def f(s):
        return baro_rows(s[0], s[1], s[3], h0, z, sd)[0][:1]
    cols = [km.IPOS + 2, km.IVEL + 2, km.ISC, km.ITD, km.IBB]
    for j, d in _fd_columns(f, state, cols, 1e-4).items():
        assert d[0] == pytest.approx(hm[0, j], rel=1e-5, abs=1e-7), j


@pytest.mark.parametrize("has_vel", [False, True])
def test_gnss_rows_match_finite_differences(has_vel):
    rng = np.random.default_rng(9)
    state = _state(rng)
    lever = np.array([0.4, -0.1, -0.8])
    fix = state[0] + np.array([3e-6, -2e-6, 1.5])
    fix_vel = state[1] + 0.3
    w = rng.normal(0.0, 0.1, 3)

    def f(s, full=False):
        lla, v, q, par = s
        c = quat_to_dcm(q)
        rn, re = radii_scalar(lla[0])
        out = gnss_rows(lla, v, c, rn, re, par[km.PGE:km.PGE + 3], lever, fix, np.full(3, 1.0),
                        fix_vel, np.full(3, 0.1), has_vel, True, w, w)
        return out if full else out[0][:out[3]]

    y, hm, r, mm = f(state, full=True)
    assert mm == (6 if has_vel else 3)
    cols = [*range(km.IPOS, km.IPOS + 3), *range(km.IVEL, km.IVEL + 3),
            *range(km.IATT, km.IATT + 3), *range(km.IGE, km.IGE + 3)]
    # the velocity rows leave out the Earth and transport rates' path through C in the lever
    # arm's velocity C(ω_nb × l): |Ω_ie| |l| ≈ 7e-5 m/s per rad of attitude error
    for j, d in _fd_columns(f, state, cols, 1e-6).items():
        np.testing.assert_allclose(d, hm[:mm, j], rtol=2e-4, atol=1e-4, err_msg=str(j))


def test_mag_row_matches_finite_differences():
    rng = np.random.default_rng(2)
    state = _state(rng)
    field = np.array([21.0, 1.5, 42.0])
    p = np.eye(km.NX) * 1e-4

    def f(s, full=False):
        c = quat_to_dcm(s[2])
        out = mag_rows(field, s[3], c, 0.05, 0.5, 1e-4, True, p, new_state())
        return out if full else out[0][:out[3]]

    y, hm, r, mm = f(state, full=True)
    assert mm == 1
    cols = [*range(km.IATT, km.IATT + 3), *range(km.IMB, km.IMB + 3)]
    for j, d in _fd_columns(f, state, cols, 1e-6).items():
        assert d[0] == pytest.approx(hm[0, j], rel=1e-3, abs=1e-6), j
