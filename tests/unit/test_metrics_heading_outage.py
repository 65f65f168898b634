"""Heading RMSE and max errors inside GNSS outages (evaluation.metrics) against planted errors."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.metrics import evaluate, outage_max
from vnav_graph.geo.frames import quat_to_rph, rph_to_quat
from vnav_graph.simulation.scenario import simulate
from vnav_graph.types import Estimate, Trajectory


@pytest.fixture(scope="module")
def drive():
    return simulate("hill-drive", 2, duration_s=400.0)  # keeps its 300-360 s outage


def _planted(drive, dyaw_deg: float, dalt_in_outage: float) -> Estimate:
    tr = drive.truth
    rph = quat_to_rph(tr.q_nb)
    rph[:, 2] += np.radians(dyaw_deg)  # wraps through ±180° for some epochs
    lla = tr.lla.copy()
    inside = np.zeros(tr.t.size, dtype=bool)
    for a, b in drive.meta["gnss_outages"]:
        inside |= (tr.t >= a) & (tr.t < b)
    lla[inside, 2] += dalt_in_outage * np.sin(np.linspace(0, np.pi, int(inside.sum())))
    return Estimate("planted", Trajectory(tr.t, lla, tr.vel_n, rph_to_quat(rph)),
                    frozenset({"alt", "vel_d", "pos_h", "vel_h", "att"}))


def test_heading_rmse_is_the_wrapped_yaw_offset(drive):
    m = evaluate(_planted(drive, 170.0, 0.0), drive)
    assert m["heading_rmse_deg"] == pytest.approx(170.0, abs=1e-6)
    m = evaluate(_planted(drive, -190.0, 0.0), drive)  # −190° is +170°: same error size
    assert m["heading_rmse_deg"] == pytest.approx(170.0, abs=1e-6)
    assert m["horiz_rmse_m"] == pytest.approx(0.0, abs=1e-6)


def test_outage_max_reads_only_the_outage_windows(drive):
    assert drive.meta["gnss_outages"] == [[300.0, 360.0]]
    m = evaluate(_planted(drive, 0.0, 4.0), drive)
    assert m["outage_alt_max_m"] == pytest.approx(4.0, abs=1e-3)
    assert m["alt_max_abs_m"] == pytest.approx(4.0, abs=1e-3)
    # a 4 m height change moves the tangent-plane NE projection by < 1 mm
    assert m["outage_horiz_max_m"] == pytest.approx(0.0, abs=1e-3)


def test_outage_max_without_windows_or_samples_is_null():
    t = np.arange(10.0)
    assert outage_max(t, np.ones(10), []) is None
    assert outage_max(t, np.ones(10), [(20.0, 30.0)]) is None
    assert outage_max(t, None, [(0.0, 5.0)]) is None
    assert outage_max(t, -np.arange(10.0), [(2.0, 5.0)]) == 4.0
