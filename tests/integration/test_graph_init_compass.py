"""The graph smoothers' initial heading from the compass (``graph.init.compass_heading``).

TRIAD takes the heading from the course, which is a car's heading but not a multirotor's
(on the Erle logs it started 39–43° from the compass). With a magnetometer in use the initial
keyframe attitudes are turned about the down axis onto the compass heading (hard iron zero,
the prior's mean). Checked here against the simulated truth, with the bound the unknown
hard iron sets, and for independence of the heading it starts from."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.model import interval_factors as gf
from vnav_graph.estimators.graph.model.initial_guess import compass_heading, initial_states
from vnav_graph.estimators.graph.model.problem import setup
from vnav_graph.geo.frames import ned_to_lla, quat_to_mat
from vnav_graph.sensors.magnetometer import drive_field, wrap_pi
from vnav_graph.simulation.scenario import simulate


@pytest.fixture(scope="module")
def mag_drive():
    return simulate("hill-drive-mag", 0, duration_s=240.0)


def _yaw_nb(P, rot, pos):
    c_tn = gf.rot_t_n(ned_to_lla(pos, P.origin), P.origin)
    c_nb = np.swapaxes(c_tn, 1, 2) @ rot
    return np.arctan2(c_nb[:, 1, 0], c_nb[:, 0, 0])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("offset_deg", [0.0, 40.0, -150.0])
def test_initial_heading_is_the_compass_within_the_hard_iron_bound(mag_drive, offset_deg):
    """From TRIAD's attitudes turned by ``offset_deg`` (a multirotor's course is not its
    heading), the compass brings every keyframe's heading back to the truth."""
    P_off = setup(mag_drive, replace(GraphConfig(), use_mag=False))
    rot, pos, _ = initial_states(P_off)
    rot = _rz(np.radians(offset_deg)) @ rot
    assert compass_heading(setup(mag_drive, GraphConfig()), rot)
    yaw = _yaw_nb(P_off, rot, pos)
    c_true = quat_to_mat(mag_drive.truth.at(P_off.t_kf).q_nb)
    yaw_true = np.arctan2(c_true[:, 1, 0], c_true[:, 0, 0])
    err = np.degrees(np.abs(wrap_pi(yaw - yaw_true)))
    # a hard iron b in the horizontal plane turns the field's azimuth by at most
    # asin(|b_h| / H); the compass noise (0.5 µT) and the ±2 s median add < 1°
    b = np.asarray(mag_drive.meta["mag_truth"]["hard_iron_ut"], float)
    ref = drive_field(mag_drive)[0].ned_ut
    bound = np.degrees(np.arcsin(np.hypot(b[0], b[1]) / np.hypot(ref[0], ref[1]))) + 2.0
    assert np.percentile(err, 95) <= bound, (np.percentile(err, 95), bound)
    assert np.median(err) < bound


@pytest.mark.parametrize("offset_deg", [40.0, 170.0, -120.0])
def test_compass_heading_does_not_depend_on_the_starting_heading(mag_drive, offset_deg):
    # TRIAD's attitudes (the magnetometer off), then the compass on them and on a turned copy
    P_off = setup(mag_drive, replace(GraphConfig(), use_mag=False))
    triad, pos, _ = initial_states(P_off)
    P = setup(mag_drive, GraphConfig())
    rot, turned = triad.copy(), _rz(np.radians(offset_deg)) @ triad
    assert compass_heading(P, rot) and compass_heading(P, turned)
    d = wrap_pi(_yaw_nb(P, turned, pos) - _yaw_nb(P, rot, pos))
    assert np.max(np.abs(d)) < 1e-9
    # the tilt is left alone: the down axis of every keyframe is TRIAD's
    np.testing.assert_allclose(rot[:, 2, :], triad[:, 2, :], atol=1e-12)


def test_without_the_magnetometer_the_heading_is_triad(mag_drive):
    P = setup(mag_drive, replace(GraphConfig(), use_mag=False))
    rot, _, _ = initial_states(P)
    before = rot.copy()
    assert not compass_heading(P, rot)
    np.testing.assert_array_equal(rot, before)
    no_mag = setup(mag_drive.replace(mag=None), GraphConfig())
    rot2, _, _ = initial_states(no_mag)
    np.testing.assert_allclose(rot2, before, atol=1e-12)
