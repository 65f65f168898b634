"""The public extension point (``graph.extend``): user factors and variables in graph-batch and
graph-isam2, incremental insertion at the keyframe where a factor's keys exist, one-line
errors for bad input."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import K, M, X

from vnav_graph.estimators.graph import GraphBatch, GraphConfig, GraphISAM2
from vnav_graph.estimators.graph.model.extend import GraphView, Terms, Variable, collect
from vnav_graph.simulation.scenario import simulate

SPAN = 10
M_PRIORS = ((0.3, 0.2), (0.6, 0.1))  # (mean, σ) of the two priors on the new scalar m0


def _m_closed_form() -> tuple[float, float]:
    """Posterior of a scalar with two independent Gaussian priors (information sum)."""
    w = np.array([1 / s**2 for _, s in M_PRIORS])
    return (float(np.sum(w * np.array([m for m, _ in M_PRIORS])) / w.sum()),
            float(1 / np.sqrt(w.sum())))


def _unit(n: int, sd: float):
    return gtsam.noiseModel.Isotropic.Sigma(n, sd)


def extension(view: GraphView) -> Terms:
    """A relative pose X(3) → X(3+SPAN) equal to the initial estimate's (off the band) and the
    scalar m0 with a Variable prior and a second prior as a CustomFactor."""
    rel = view.values.atPose3(X(3)).between(view.values.atPose3(X(3 + SPAN)))
    (m1, s1), (m2, s2) = M_PRIORS

    def m_err(this, values, jac):
        if jac is not None:
            jac[0] = np.ones((1, 1))
        return values.atVector(this.keys()[0]) - m2

    return Terms(
        [gtsam.BetweenFactorPose3(X(3), X(3 + SPAN), rel, gtsam.noiseModel.Diagonal.Sigmas(
            np.r_[[0.05] * 3, [2.0] * 3])),
         gtsam.CustomFactor(_unit(1, s2), [M(0)], m_err)],
        [Variable(M(0), 0.0, s1, prior_mean=m1)])


@pytest.fixture(scope="module")
def runs():
    d = simulate("hill-drive", 5, duration_s=90.0)
    cfg = GraphConfig(cov_epochs=20)
    return (d, GraphBatch(cfg, extensions=[extension]).run(d),
            GraphISAM2(cfg, extensions=[extension]).run(d), GraphISAM2(cfg).run(d))


def test_isam2_final_equals_batch_with_extensions(runs):
    d, eb, ei, _ = runs
    assert eb.info["solver"] == ei.info["solver_final"] == "general"  # X3–X13 is off the band
    # same tolerance as the plain iSAM2 = batch test (both stop at rel. cost change 1e-7)
    np.testing.assert_allclose(ei.trajectory.alt, eb.trajectory.alt, atol=0.01)
    mean, sd = _m_closed_form()
    for e in (eb, ei):
        m = e.info["extra_variables"]["m0"]
        assert m["est"][0] == pytest.approx(mean, abs=1e-9)
        assert m["sd"][0] == pytest.approx(sd, rel=1e-9)
    # iSAM2's own estimate of m0 (marginalCovariance): a linear problem, exact as well
    m = ei.info["extra_variables_online"]["m0"]
    assert m["est"][0] == pytest.approx(mean, abs=1e-9)
    assert m["sd"][0] == pytest.approx(sd, rel=1e-6)


def test_isam2_adds_a_factor_when_its_last_keyframe_exists(runs):
    """Causal insertion: before keyframe 3+SPAN the online estimate is the one without the
    extension (m0 is disconnected from the keyframes); from there on the factor acts."""
    _, _, ei, e0 = runs
    n = 3 + SPAN
    np.testing.assert_allclose(ei.online.alt[:n], e0.online.alt[:n], atol=1e-9)
    np.testing.assert_allclose(ei.online.lla[:n, :2], e0.online.lla[:n, :2], atol=1e-12)
    assert np.max(np.abs(ei.online.alt[n:] - e0.online.alt[n:])) > 1e-6


def test_ready_keyframe_and_first_use():
    view = GraphView(None, np.arange(20.0), np.zeros(3), True, gtsam.Values())
    g = gtsam.BetweenFactorPose3(X(2), X(14), gtsam.Pose3(), _unit(6, 1.0))
    h = gtsam.PriorFactorVector(M(1), np.zeros(1), _unit(1, 1.0))
    pr = gtsam.BetweenFactorVector(M(1), M(2), np.zeros(1), _unit(1, 1.0))

    def ext(v):
        return Terms([g, h, pr, gtsam.PriorFactorPose3(X(7), gtsam.Pose3(), _unit(6, 1.0))],
                     [Variable(M(1), 0.0, 1.0), Variable(M(2), [0.0], [1.0]),
                      Variable(M(3), gtsam.Rot3(), 0.1)])

    col = collect([ext], view)
    assert col.ready == [14, 0, 0, 7]
    assert col.first == {M(1): 0, M(2): 0, M(3): 0}
    fs, vals = col.at_keyframe(14)
    assert fs == [g] and vals.size() == 0
    fs, vals = col.at_keyframe(0)
    assert vals.size() == 3 and len(fs) == 2 + 3  # h, pr and the three priors

    def ext2(v):  # a variable used only by factors ready at keyframes 9 and 12 enters at 9
        cf = [gtsam.CustomFactor(_unit(1, 1.0), [X(k), M(5)], lambda t, vals, j: np.zeros(1))
              for k in (12, 9)]
        return Terms(cf, [Variable(M(4), 0.0, 1.0), Variable(M(5), 0.0, 1.0)])

    col = collect([ext2], view)
    assert col.ready == [12, 9]
    assert col.first == {M(4): 0, M(5): 9}
    fs, vals = col.at_keyframe(9)
    assert vals.keys() == [M(5)] and len(fs) == 2  # the factor and M(5)'s prior


BAD = [
    ("not callable", [3], "is not callable"),
    ("single", extension, "a list of callables"),
    ("wrong return", [lambda v: [1]], "expected graph.extend.Terms"),
    ("not a factor", [lambda v: Terms(["f"])], "gtsam.NonlinearFactor"),
    ("unknown key", [lambda v: Terms([gtsam.PriorFactorVector(M(9), np.zeros(1),
                                                             _unit(1, 1.0))])],
     "nor a declared Variable"),
    ("index range", [lambda v: Terms([gtsam.PriorFactorPose3(X(10**6), gtsam.Pose3(),
                                                            _unit(6, 1.0))])],
     "out of range"),
    ("calibration", [lambda v: Terms([gtsam.PriorFactorVector(K(0), np.zeros(2),
                                                             _unit(2, 1.0))])],
     "baro calibration"),
    ("reserved", [lambda v: Terms([], [Variable(X(10**6), np.zeros(1), 1.0)])], "reserved"),
    ("prior size", [lambda v: Terms([], [Variable(M(0), np.zeros(3), [1.0, 2.0])])],
     "prior_sd must be 3"),
    ("duplicate", [lambda v: Terms([], [Variable(M(0), 0.0, 1.0)] * 2)], "declared twice"),
    ("value", [lambda v: Terms([], [Variable(M(0), "a", 1.0)])], "value must be a finite vector"),
]


@pytest.mark.parametrize("what, exts, match", BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_error(what, exts, match):
    d = simulate("hill-drive", 1, duration_s=30.0)
    with pytest.raises(ValueError, match=match) as exc:
        GraphBatch(extensions=exts).run(d)
    assert "\n" not in str(exc.value)


def test_extra_variables_reach_summary_json(runs):
    import json

    from vnav_graph.run.pipeline import RunResult, summarize

    d, eb, ei, e0 = runs
    s = json.loads(json.dumps(summarize(d, [RunResult(e.estimator + tag, e, None, e.runtime_s)
                                            for e, tag in ((eb, ""), (ei, ""), (e0, "-0"))])))
    mean, sd = _m_closed_form()
    for name in ("graph-batch", "graph-isam2"):
        m = s["estimators"][name]["extra_variables"]["m0"]
        assert m["est"][0] == pytest.approx(mean, abs=1e-9)
        assert m["sd"][0] == pytest.approx(sd, rel=1e-9)
    assert s["estimators"]["graph-isam2-0"]["extra_variables"] is None  # null, not omitted
