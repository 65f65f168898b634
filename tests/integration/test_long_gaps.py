"""Logging gaps longer than one baro-calibration segment.

graph-isam2 numbered its calibration segments by time (``floor(t / segment_s)``) and
assumed the next keyframe is at most one segment later: a gap longer than ``segment_s``
(60 s) made the next K(j) read ``cal[j - 1]``, which was never created (``KeyError``).
"""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.graph import GraphBatch, GraphISAM2
from vnav_graph.evaluation.metrics import errors_vs_truth
from vnav_graph.simulation import simulate
from vnav_graph.types.streams import ImuStream


def _with_imu_gap(duration_s: float, t0: float, t1: float):
    d = simulate("hill-drive", 3, duration_s=duration_s)
    keep = ~((d.imu.t > t0) & (d.imu.t < t1))
    return d, d.replace(imu=ImuStream(d.imu.t[keep], d.imu.gyro_b[keep], d.imu.accel_b[keep],
                                      d.imu.spec))


@pytest.mark.slow
def test_isam2_survives_an_imu_gap_of_two_and_a_half_segments():
    truth_drive, d = _with_imu_gap(300.0, 60.0, 210.0)  # 150 s hole: segments 1 and 2 empty
    e = GraphISAM2().run(d)
    # keyframes fall in the 60 s segments 0, 1 (t = 60 s), 3, 4 and 5 (t = 300 s): five
    # numbered densely; the old numbering by time asked for K(3) with no K(2) (KeyError)
    assert e.info["segments"] == 5
    alt = errors_vs_truth(e, truth_drive).alt
    rmse = float(np.sqrt(np.mean(alt**2)))
    # graph-batch on the same drive is the reference: measured 0.77 m (isam2) against
    # 0.69 m (batch); the final pass starts from the iSAM2 estimate, so it need not be equal
    ref = float(np.sqrt(np.mean(errors_vs_truth(GraphBatch().run(d), truth_drive).alt**2)))
    assert rmse < 1.25 * ref
    assert rmse < 1.5  # GNSS-aided: metre level even across a 150 s hole


def _all_stream_gap(seed: int, t0: float, gap: float, outage: float = 60.0):
    """hill-drive with GNSS out for ``outage`` s before t0 and every stream (IMU, baro, GNSS)
    missing for ``gap`` s from t0: a logger that stopped right after a GNSS outage."""
    from vnav_graph.types.streams import ImuStream as Imu

    d0 = simulate("hill-drive", seed, duration_s=360.0)
    k = ~((d0.imu.t > t0) & (d0.imu.t < t0 + gap))
    g, b = d0.gnss, d0.baro
    d = d0.replace(imu=Imu(d0.imu.t[k], d0.imu.gyro_b[k], d0.imu.accel_b[k], d0.imu.spec),
                   gnss=g.select(~((g.t > t0 - outage) & (g.t < t0 + gap))),
                   baro=b.select(~((b.t > t0) & (b.t < t0 + gap))))
    return d0, d


@pytest.mark.slow
@pytest.mark.parametrize("gap", [11.0, 30.0])
def test_graph_bridges_an_all_stream_gap_as_well_as_ekf_rts(gap: float) -> None:
    """At the first epoch after the gap the graph's horizontal error is no larger than
    ekf-rts's by more than 5 cm and its altitude error ties (measured on seed 2: horizontal
    0.141 against 0.173 m after 11 s, 0.129 against 0.118 m after 30 s, both well inside
    their reported σ; altitude equal within 3 mm)."""
    from vnav_graph.estimators.base import create
    from vnav_graph.geo.frames import lla_to_ned

    t0 = 200.0
    truth, d = _all_stream_gap(2, t0, gap)
    err = {}
    for name in ("ekf-rts", "graph-batch"):
        tr = create(name).run(d).trajectory
        j = int(np.searchsorted(tr.t, t0 + gap))
        ref = truth.truth.at(tr.t[j:j + 1])
        dn = (lla_to_ned(tr.lla[j:j + 1], truth.origin_lla)
              - lla_to_ned(ref.lla, truth.origin_lla))[0]
        err[name] = (abs(float(dn[2])), float(np.hypot(dn[0], dn[1])))
    assert err["graph-batch"][1] <= err["ekf-rts"][1] + 0.05
    assert err["graph-batch"][0] <= err["ekf-rts"][0] + 0.02  # the GNSS-free height: a tie


@pytest.mark.slow
def test_isam2_own_estimate_is_the_batch_optimum_across_an_imu_gap():
    """iSAM2's own smoothed estimate is checked under the batch's cost at its own states.
    Two faults made every drive with an IMU logging gap fall back to the batch pass:

    - ``build_batch_graph`` starts the keyframe after a gap at its gap prior, and the check
      took that start instead of iSAM2's estimate there (this drive: a false cost gap of
      17.5e6 against 7285; Loiter_RTL holdout: 6141 against 370);
    - the batch's post-solve GNSS gate rejected 7 fixes around the gap that iSAM2 kept: its
      estimate was up to 0.5 m from the batch optimum (gap 26, n = 2674). The same gate now
      runs at iSAM2's estimate before its last rounds.

    Measured after both: gap 0.23, 5 mm apart, the 7 fixes rejected by iSAM2's own gate (with
    the online gate: 10 fixes, all by it, none left for the final rounds' gate)."""
    _, d = _with_imu_gap(180.0, 80.0, 95.0)
    info = GraphISAM2().run(d).info
    fb = info["final_batch"]
    assert info["trajectory_source"] == "isam2" and info["warnings"] == []
    assert fb["cost_gap"] < 0.002 * fb["dimension"], fb
    assert fb["max_horizontal_diff_m"] < 0.05 and fb["max_alt_diff_m"] < 0.05
    # refused by iSAM2's own gates (after its updates, and in its final rounds), and none more
    # by the batch check
    assert (info["isam2_gnss_rejected_online"] + info["isam2_gnss_rejected_postsolve"]
            == info["gnss_rejected_postsolve"] > 0)
