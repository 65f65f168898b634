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


# ------------------------------------------------------------ after an outage, every answer
def _outage(drive, t0, t1):
    """``drive`` with its GNSS fixes in (t0, t1) removed: a receiver outage."""
    g = drive.gnss
    return drive.replace(gnss=g.select(~((g.t > t0) & (g.t < t1))))


def _with_sigma(e, sd_m):
    t_cov = e.trajectory.t[::10]
    return e.replace(cov=np.tile(np.eye(18) * sd_m**2, (t_cov.size, 1, 1)), t_cov=t_cov)


def test_outage_jump_beyond_five_sigma_plus_floor_is_flagged(drive):
    """A height answer 300 m off over the last 20 s of a 60 s outage, σ 2 m: the jump to the
    first fix after it is 300 m = 150 σ, beyond 5σ + 100 m: flagged, kept "ok" (back on the
    fixes at once); the same 300 m with an honest σ of 100 m (3σ) is not flagged."""
    from vnav_graph.evaluation.selfcheck import JUMP_FLOOR_M, JUMP_SIGMA

    d = _outage(drive, 40.0, 100.0)
    e = _est(drive, d_alt=300.0, t_from=80.0, t_to=100.0)
    c = self_check(_with_sigma(e, 2.0), d)
    assert not c.diverged
    assert len(c.jumps) == 1 and c.jumps[0]["kind"] == "height"
    j = c.jumps[0]
    assert 295.0 < j["jump_m"] < 305.0 and 57.0 < j["outage_s"] < 61.0
    assert j["limit_m"] == pytest.approx(JUMP_SIGMA * j["sigma_m"] + JUMP_FLOOR_M)
    assert c.flags and c.flags[0].startswith("height jump of 300 m to the first GNSS fix")
    assert not self_check(_with_sigma(e, 100.0), d).jumps
    # no outage: the same 20 s excursion is a residual, not a jump
    assert not self_check(_with_sigma(e, 2.0), drive).jumps


def test_outage_jump_beyond_its_limit_and_a_kilometre_is_diverged(drive):
    """2 km north over the last 20 s of the outage. With σ 100 m per axis (141 m
    horizontally) the jump is 14σ, beyond 5σ + 100 m and beyond LOST_M: diverged. With σ
    500 m per axis the limit is 5 x 707 + 100 = 3,636 m: an answer that says it may be that
    far off is not flagged by the jump (truth or withheld fixes still judge it: far_off)."""
    d = _outage(drive, 40.0, 100.0)
    e = _est(drive, d_north_rad=2000.0 / 6.37e6, t_from=80.0, t_to=100.0)
    c = self_check(_with_sigma(e, 100.0), d)
    assert c.diverged and c.reason.startswith("horizontal jump of 2001 m")
    assert "(14 x its own sigma of 141 m" in c.reason
    assert "more than 1000 m off for the length of the outage" in c.reason
    assert not self_check(_with_sigma(e, 500.0), d).diverged


def test_online_answer_is_checked_too(drive):
    """A final answer on the fixes and a causal one 2 km off for 60 s: diverged, and the
    reason says it was the online answer."""
    from vnav_graph.evaluation.selfcheck import check_answers

    good = _est(drive)
    bad = _est(drive, d_alt=2000.0, t_from=60.0)
    c = check_answers(good, bad, drive)
    assert c.diverged and c.reason.startswith("online answer: height residual")
    assert c.online is not None and c.online.diverged
    assert c.as_dict()["online"]["diverged"]
    assert not check_answers(good, good, drive).diverged
    assert not check_answers(good, None, drive).diverged


def test_far_off_against_a_reference():
    from vnav_graph.evaluation.selfcheck import far_off

    assert far_off({"height": 999.0, "horizontal": None}, "truth") is None
    why = far_off({"height": 12.0, "online_horizontal": 1126.0}, "truth")
    assert why.startswith("online_horizontal error up to 1126 m against truth")
