"""Logging gaps longer than one baro-calibration segment (issue 16).

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
from vnav_graph.types import ImuStream


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
