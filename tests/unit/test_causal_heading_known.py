"""``heading_known`` in the causal (``online``) blocks: scored from the causal estimate's own
covariance, the top-level block's definition and clock; and the common-span scoring of two
causal estimates (``montecarlo.common_start_blocks``)."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.metrics import (
    causal_block,
    causal_errors,
    causal_metrics,
    evaluate,
)
from vnav_graph.evaluation.montecarlo import (
    CAUSAL_ERRORS_KEY,
    common_start_blocks,
    shorten_scenario,
)
from vnav_graph.nav.rotations import rpy_quat
from vnav_graph.simulation import simulate
from vnav_graph.types import ERROR_STATE, Estimate, Trajectory

T_KNOWN = 7.0  # σ_yaw is 30° before, 2° from this time on [s after the drive's start]
OFF_EARLY, OFF_LATE = 60.0, 3.0  # yaw error before / after T_KNOWN [deg]


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive", 30.0), 0)


def yawed(drive, t, offset_deg):
    """The truth at ``t`` with its yaw turned by ``offset_deg`` [deg] (per epoch)."""
    tr = drive.truth.at(t)
    rph = tr.to_rph()
    q = np.array([rpy_quat(r, p, y + np.radians(o))
                  for (r, p, y), o in zip(rph, offset_deg, strict=True)])
    return Trajectory(t, tr.lla, tr.vel_n, q)


def synthetic(drive, name="ekf", t_start=0.0):
    """An Estimate whose online estimate is the truth turned in yaw, with a covariance whose
    σ_yaw is 30° before ``T_KNOWN`` and 2° from it on (everything else 1 m, 1 m/s, 1 mrad)."""
    t = np.arange(t_start, drive.truth.t[-1], 0.5)
    off = np.where(t < T_KNOWN, OFF_EARLY, OFF_LATE)
    tr = yawed(drive, t, off)
    cov = np.tile(np.eye(18), (t.size, 1, 1))
    cov[:, 6:9, 6:9] *= 1e-6
    yaw = ERROR_STATE["att_n"].start + 2
    cov[:, yaw, yaw] = np.radians(np.where(t < T_KNOWN, 30.0, 2.0)) ** 2
    prov = frozenset({"alt", "vel_d", "pos_h", "vel_h", "att", "cov"})
    return Estimate(name, tr, prov, cov=cov, t_cov=t, online=tr, online_cov=cov)


def test_online_heading_known_excludes_exactly_the_unknown_epochs(drive):
    on = causal_block(synthetic(drive), drive, "online")
    # closed form: 3° over every epoch from T_KNOWN on, none of the 60° epochs
    assert on["heading_known_rmse_deg"] == pytest.approx(OFF_LATE, rel=1e-6)
    assert on["heading_known_after_s"] == pytest.approx(T_KNOWN)
    # the plain RMS keeps them: 14 epochs at 60°, the rest at 3°
    t = np.arange(0.0, drive.truth.t[-1], 0.5)
    w = np.where(t < T_KNOWN, OFF_EARLY, OFF_LATE)
    assert on["heading_rmse_deg"] == pytest.approx(np.sqrt(np.mean(w**2)), rel=1e-6)


def test_after_s_counts_from_the_drive_start_not_the_estimate_start(drive):
    # an online estimate that starts at 4 s (an aligned filter): same clock as the summary
    on = causal_block(synthetic(drive, t_start=4.0), drive, "online")
    assert on["from_s"] == pytest.approx(4.0)
    assert on["heading_known_after_s"] == pytest.approx(T_KNOWN)


def test_common_span_scores_from_the_later_first_epoch(drive):
    ce = causal_errors(synthetic(drive), drive, "online")
    late = causal_metrics(ce, 10.0)  # from 10 s only the 3° epochs remain
    assert late["heading_rmse_deg"] == pytest.approx(OFF_LATE, rel=1e-6)
    assert late["heading_known_after_s"] == pytest.approx(10.0)
    rows = [{"scenario": "s", "seed": 0, "estimator": n, "status": "ok",
             CAUSAL_ERRORS_KEY: causal_errors(synthetic(drive, n, t0), drive, "online")}
            for n, t0 in (("early", 0.0), ("late", 10.0))]
    rows.append({"scenario": "s", "seed": 0, "estimator": "smoother", "status": "ok",
                 CAUSAL_ERRORS_KEY: None})
    out = common_start_blocks(rows)
    assert all(CAUSAL_ERRORS_KEY not in r for r in out)
    early, late_row, smoother = out
    assert set(early["online_common"]) == {"late"}
    assert early["online_common"]["late"]["from_s"] == pytest.approx(10.0)
    assert early["online_common"]["late"]["heading_rmse_deg"] == pytest.approx(OFF_LATE)
    assert late_row["online_common"] == {}  # its own online block is its common score
    assert smoother["online_common"] is None


def test_ekf_online_heading_known_equals_its_top_level_one(drive):
    """When the trajectory is the filter's own output at its covariance epochs, the online
    block and the summary block score the same states with the same σ: equal values."""
    from vnav_graph.estimators.base import with_online
    from vnav_graph.run.runner import run_one

    d = simulate(shorten_scenario("hill-drive", 90.0), 1)
    est = run_one("ekf", d, None, interrupts=False).estimate
    filt = est.replace(trajectory=est.online, cov=est.online_cov, t_cov=est.online.t,
                       online=None, online_cov=None)
    filt = with_online("ekf", filt)
    block = evaluate(filt, d)
    on = block["online"]
    assert on["from_s"] >= 5.0  # aligned after the levelling window: a later start
    assert block["heading_known_after_s"] is not None
    assert block["heading_known_after_s"] > on["from_s"]  # acquired in motion
    assert on["heading_known_after_s"] == block["heading_known_after_s"]
    assert on["heading_known_rmse_deg"] == pytest.approx(block["heading_known_rmse_deg"],
                                                         rel=1e-12)
