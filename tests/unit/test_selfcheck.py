"""The self-check against the GNSS fixes an estimator was given: a consistent estimate passes,
a sustained kilometre error is "diverged", a few seconds' excursion and a modest error with
an overconfident σ are not."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.selfcheck import (
    DIVERGED_WINDOWS,
    RESID_FLOOR_M,
    WINDOW_S,
    Z_DIVERGED,
    self_check,
)
from vnav_graph.simulation import simulate
from vnav_graph.types import Estimate, Trajectory


@pytest.fixture(scope="module")
def drive():
    return simulate("default", 0, duration_s=150.0)


def _est(drive, d_alt=0.0, d_north_rad=0.0, t_from=-np.inf, t_to=np.inf):
    tr = drive.truth
    m = (tr.t >= t_from) & (tr.t <= t_to)
    lla = tr.lla.copy()
    lla[m, 2] += d_alt
    lla[m, 0] += d_north_rad
    return Estimate("x", Trajectory(tr.t, lla, tr.vel_n, tr.q_nb),
                    frozenset({"alt", "vel_d", "pos_h", "vel_h"}))


def test_truth_is_consistent_with_its_fixes(drive):
    c = self_check(_est(drive), drive)
    assert not c.diverged and c.reason is None
    assert c.worst_z < 3.0 and c.windows >= 4


def test_sustained_kilometre_height_error_is_diverged(drive):
    c = self_check(_est(drive, d_alt=2000.0, t_from=30.0), drive)
    assert c.diverged
    assert c.reason.startswith("height residual to the GNSS fixes it was given: median 2000 m")
    assert c.worst_z > Z_DIVERGED


def test_horizontal_divergence(drive):
    c = self_check(_est(drive, d_north_rad=5000.0 / 6.37e6, t_from=20.0), drive)
    assert c.diverged and c.reason.startswith("horizontal residual")


def test_a_short_excursion_and_an_overconfident_small_error_are_not_divergence(drive):
    # 10 s at 2 km: at most one window
    assert WINDOW_S * DIVERGED_WINDOWS > 10.0
    assert not self_check(_est(drive, d_alt=2000.0, t_from=40.0, t_to=50.0), drive).diverged
    # 40 m for the whole drive: many sigma of GNSS noise, but under the physical floor
    assert RESID_FLOOR_M > 40.0
    assert not self_check(_est(drive, d_alt=40.0), drive).diverged


def test_no_gnss_nothing_to_check(drive):
    c = self_check(_est(drive, d_alt=5000.0), drive.replace(gnss=None))
    assert not c.diverged and c.windows == 0 and c.worst_z is None


def test_lost_whatever_its_sigma(drive):
    """Kilometres from the fixes for over 30 s is divergence even when σ claims as much
    (z stays under the limit): the estimate lost its measurements."""
    from vnav_graph.evaluation.selfcheck import LOST_M, LOST_S

    e = _est(drive, d_alt=2000.0, t_from=60.0)
    t_cov = e.trajectory.t[::50]
    cov = np.tile(np.eye(18) * 5000.0**2, (t_cov.size, 1, 1))  # σ 5 km everywhere
    c = self_check(e.replace(cov=cov, t_cov=t_cov), drive)
    assert c.worst_z < Z_DIVERGED  # not outside its own σ...
    assert c.diverged and "above 1000 m for" in c.reason and "lost" in c.reason
    assert LOST_M == 1000.0 and LOST_S == 30.0
    # the same offset for 20 s only: not lost
    e2 = _est(drive, d_alt=2000.0, t_from=60.0, t_to=80.0)
    assert not self_check(e2.replace(cov=cov, t_cov=t_cov), drive).diverged
