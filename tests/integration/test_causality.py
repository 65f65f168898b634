"""Causality of every online estimate: a state at t is computed from data up to t only.

The check is the definition: run an estimator on a drive cut at T1 and on the same drive cut at
T2 > T1; its online outputs (``Estimate.online``, filled by ``runner.run_captured``) must agree
over t < T1 (the last epoch of the cut drive is left out: it may see a sample at T1 the longer
drive processes later in the same step). The drive stands still for its first 40 s, so T1 =
30 s tests the opening standstill (the ekf levels over its first 20 s and is online from there:
``info["online_from_s"]``) and T1 = 60 s the drive. Height, horizontal position, down velocity
and heading are compared; the smoothed ekf-rts trajectory, which is not causal, changes under
the same cut (the check has teeth).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.estimators.base import CAUSAL
from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.run.runner import run_captured
from vnav_graph.simulation.scenario import load_scenario, simulate
from vnav_graph.types import Drive, Estimate

pytestmark = pytest.mark.slow

STANDSTILL_S = 40.0
T2 = 75.0
CUTS = (30.0, 60.0)  # in the opening standstill, and driving
ATOL_M = 1e-6  # height, north/east [m]; down velocity [m/s]
ATOL_DEG = 1e-6  # heading


def cut(drive: Drive, t1: float) -> Drive:
    """The drive with every stream and the truth ending at ``t0 + t1``."""
    return drive.until(float(drive.imu.t[0]) + t1)


@pytest.fixture(scope="module")
def drive() -> Drive:
    cfg = load_scenario("hill-drive", duration_s=T2)
    cfg = replace(cfg, params={**cfg.params, "static_s": STANDSTILL_S})
    return simulate(cfg, seed=4)


_RUNS: dict[tuple[str, float], Estimate] = {}


def run(drive: Drive, name: str, t1: float) -> Estimate:
    if (name, t1) not in _RUNS:
        _RUNS[(name, t1)] = run_captured(name, cut(drive, t1))
    return _RUNS[(name, t1)]


def differences(a, b, t1: float, origin) -> dict[str, float]:
    """Max |a − b| of the online quantities over the epochs of ``a`` before ``t1``."""
    n = int(np.searchsorted(a.t, a.t[0] + t1 - 1e-9)) - 1
    n = min(n, a.t.size - 1)
    assert n >= 5, "too few epochs to compare"
    np.testing.assert_array_equal(a.t[:n], b.t[:n])
    out = {"alt": float(np.max(np.abs(a.alt[:n] - b.alt[:n]))),
           "vel_down": float(np.max(np.abs(a.vel_down[:n] - b.vel_down[:n])))}
    if np.all(np.isfinite(a.lla[:n, :2])):
        d = lla_to_ned(a.lla[:n], origin)[:, :2] - lla_to_ned(b.lla[:n], origin)[:, :2]
        out["horiz"] = float(np.max(np.abs(d)))
    if a.q_nb is not None:
        dy = a.to_rph()[:n, 2] - b.to_rph()[:n, 2]
        out["heading"] = float(np.max(np.abs(np.degrees((dy + np.pi) % (2 * np.pi) - np.pi))))
    return out


CASES = [(n, t1, q) for n in [*sorted(CAUSAL), "graph-isam2"] for t1 in CUTS
         for q in ("position", "heading")
         if q == "position" or n in ("ekf", "graph-isam2")]


@pytest.mark.parametrize("name, t1, quantity", CASES)
def test_online_does_not_change_when_the_drive_is_cut_later(drive, name, t1, quantity):
    short, full = run(drive, name, t1), run(drive, name, T2)
    assert short.online is not None and full.online is not None
    d = differences(short.online, full.online, t1, drive.origin_lla)
    if quantity == "heading":
        assert d["heading"] <= ATOL_DEG, d
    else:
        for k in ("alt", "vel_down", "horiz"):
            if k in d:
                assert d[k] <= ATOL_M, (k, d)
    if t1 < STANDSTILL_S:  # the compared epochs include the opening standstill
        assert short.online.t[0] < t1 - 5.0


def test_the_ekf_is_online_once_aligned(drive):
    """The ekf's online estimate starts where its alignment stopped reading data (the end of
    the levelling window, 20 s here, after its first 9 fixes), inside the standstill; its
    covariance is at the online epochs."""
    e = run(drive, "ekf", T2)
    assert e.info["online_from_s"] == pytest.approx(20.0, abs=0.01)
    assert e.online.t[0] >= e.info["online_from_s"]
    assert e.online.t[0] < e.info["online_from_s"] + 1.5  # the next covariance epoch
    assert e.online_cov is not None and e.online_cov.shape == (e.online.t.size, 18, 18)
    j = np.searchsorted(e.t_cov, e.online.t)
    np.testing.assert_array_equal(e.online_cov, e.cov[j])


def test_a_smoothed_trajectory_changes_when_the_drive_is_cut_later(drive):
    """The same comparison on ekf-rts's smoothed trajectory, which uses later data, finds
    differences far above the tolerance: the causality check can fail."""
    short, full = run(drive, "ekf-rts", 60.0), run(drive, "ekf-rts", T2)
    d = differences(short.trajectory, full.trajectory, 60.0, drive.origin_lla)
    assert max(d["alt"], d["horiz"]) > 1e3 * ATOL_M, d
