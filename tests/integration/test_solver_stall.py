"""graph-batch's Gauss-Newton does not call a stall converged while its own quadratic model
still predicts a large decrease (``solve.STALL_MAX_PREDICTED``).

On the ski phone log with 0.25 s keyframes and the holdout's 60 s windows withheld, the
solve used to stop "converged" after 20 iterations at ½χ² 178.77: its last full step gained
0.04 (< abs_tol) while the model before it predicted 25. The gyro bias and heading of the
two windows lie in a curved valley where the full step overshoots (cost +23 000) and the
damped steps creep; 280 more iterations reach 159.7, and the altitude in the first window
moves by 3 m (withheld-fix RMSE 3.1 → 0.7 m; ekf-rts 0.63 m)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gtsam.symbol_shorthand import K

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.model.builtin_sensors import builtin_extensions
from vnav_graph.estimators.graph.model.cpp_factors import build_batch_graph, pims_for
from vnav_graph.estimators.graph.model.extend import collect, make_view
from vnav_graph.estimators.graph.model.initial_guess import initial_states
from vnav_graph.estimators.graph.model.problem import interval_rows, setup, states_from_values
from vnav_graph.estimators.graph.settings import low_rate_config
from vnav_graph.estimators.graph.solver import solve as solve
from vnav_graph.estimators.graph.solver.layout import interval_info
from vnav_graph.estimators.graph.solver.outputs import outputs
from vnav_graph.evaluation.holdout import choose_windows, withhold


def _held(data_dir: Path):  # noqa: ANN202
    from vnav_graph.io import load_drive

    p = data_dir / "ski_iphone_100hz"
    if not p.exists():
        pytest.skip("ski_iphone_100hz not present (real logs are not shipped)")
    d = load_drive(p)
    return d, withhold(d, choose_windows(d.gnss.t, 60.0, None))


@pytest.mark.slow
def test_a_stall_with_a_large_predicted_decrease_is_not_convergence(data_dir: Path) -> None:
    d, held = _held(data_dir)
    cfg = GraphConfig(keyframe_dt=0.25, gnss_gate_prob=0.0)
    P = setup(held, low_rate_config(cfg, held))
    rot, pos, vel = initial_states(P)
    calib = np.zeros(P.n_kf, dtype=int)
    graph, vals = build_batch_graph(P, rot, pos, vel, pims_for(P, rot, pos), P.pri, calib)
    collect(builtin_extensions(held, cfg), make_view(P, vals)).add_to_batch(graph, vals)
    res = solve.gn_core(P, solve.batch_layout(P, graph, vals), graph, vals, calib, P.pri)
    # the model's predicted decrease at the returned point
    st = states_from_values(P, res.values, calib)
    info = interval_info(res.layout, interval_rows(P, st, P.pri, res.bias_lag))
    system = solve.linear_system(P, res.layout, graph, res.values, info)
    _, dec = system.step()
    if res.converged:  # converged means the model sees (almost) nothing left
        assert dec < solve.STALL_MAX_PREDICTED
        assert res.predicted_decrease < solve.STALL_MAX_PREDICTED
    else:
        assert res.stop == "max_iterations"
        assert res.predicted_decrease > 0.0  # reported with the cap's warning
    # and the first withheld window's altitude is the better point's (before: 3.1 m); the
    # trajectory of this solve (GraphBatch.run with these settings solves the same problem
    # again: no post-solve gate, no magnetometer in this export)
    g, t = d.gnss, outputs(P, res, P.pri, K(0))["trajectory"]
    w1 = (g.t > held.meta["gnss_holdout_windows"][0][0]) & \
        (g.t < held.meta["gnss_holdout_windows"][0][1])
    err = np.interp(g.t[w1], t.t, t.lla[:, 2]) - g.lla[w1, 2]
    assert float(np.sqrt(np.mean(err**2))) < 1.5
