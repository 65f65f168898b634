"""The EKF's forced-in GNSS fixes are counted and said: ``info["gnss_forced"]``, a warning,
and ``gnss_forced`` in the summary block."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf.filter import EKF, max_rejects
from vnav_graph.estimators.ekf.settings import EkfConfig
from vnav_graph.evaluation.metrics import evaluate
from vnav_graph.simulation import simulate
from vnav_graph.types.streams import GnssStream

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def drives():
    d = simulate("hill-drive", 2, duration_s=150.0)
    g = d.gnss
    lla = g.lla.copy()
    lla[g.t >= g.t[0] + 80.0, 0] += np.radians(200.0 / 111_320.0)  # a lasting 200 m shift
    return d, d.replace(gnss=GnssStream(g.t, lla, g.pos_sd, g.vel_n, g.vel_sd,
                                        g.lever_arm_b, g.spec))


def test_a_lasting_shift_is_forced_in_and_counted(drives):
    """The ekf refuses the shifted fixes, then forces the next ones in after
    ``max_rejects`` refusals in a row; the clean drive forces none."""
    clean, shifted = drives
    e0, e1 = EKF().run(clean), EKF().run(shifted)
    assert e0.info["gnss_forced"] == 0
    assert not any("forced in" in w for w in e0.info.get("warnings") or [])
    n = e1.info["gnss_forced"]
    assert n >= 1
    assert e1.info["gnss_rejected"] >= max_rejects(EkfConfig(), shifted)
    assert any(f"{n} GNSS fix(es) forced in" in w for w in e1.info["warnings"])
    assert evaluate(e1, shifted)["gnss_forced"] == n
