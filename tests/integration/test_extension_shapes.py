"""A graph extension whose factor fills a Jacobian of the wrong shape: GTSAM's C++ would crash
in ``linearize`` (a segmentation fault with gtsam 4.3). Each factor is evaluated once in Python
at the initial values with its shapes checked, so a ``run`` stops with one line naming the
extension, exit 2, nothing written. Run in a subprocess: a regression would kill the test
process otherwise."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V

from vnav_graph.estimators.graph import GraphBatch
from vnav_graph.estimators.graph.model.extend import Terms
from vnav_graph.simulation import simulate
from vnav_graph.util.failures import ExtensionError

PLUGIN = textwrap.dedent('''
    import gtsam, numpy as np
    from vnav_graph.estimators.graph import GraphBatch, GraphISAM2
    from vnav_graph.estimators.graph.model.extend import Terms, V

    def wrong_velocity(view):
        def err(this, values, h):
            if h is not None:
                h[0] = np.eye(2)  # V(3) has 3 tangent components: (3, 3) is right
            return np.asarray(values.atVector(this.keys()[0]), float)
        return Terms(factors=[gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, 1.0),
                                                 [V(3)], err)])

    class BadBatch(GraphBatch):
        def __init__(self, config=None):
            super().__init__(config, extensions=[wrong_velocity])

    class BadIsam(GraphISAM2):
        def __init__(self, config=None):
            super().__init__(config, extensions=[wrong_velocity])
''')
WANT = ("vnav-graph: error: graph extension 0 (wrong_velocity): its factor on v3: the Jacobian "
        "of v3 has shape (2, 2), expected (3, 3)\n")


@pytest.mark.parametrize("cls", ["BadBatch", "BadIsam"])
def test_wrong_jacobian_shape_in_a_run_is_one_line_exit_2(tmp_path, cls):
    plugin = tmp_path / "badjac.py"
    plugin.write_text(PLUGIN)
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "vnav_graph", "run", "--duration", "20",
                        "--no-progress", "--plugin", f"bad={plugin}:{cls}",
                        "--estimators", "vkf4,bad", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr == WANT
    assert not out.exists()


def _factor(err_dim: int, fill):
    def err(this, values, h):
        if h is not None:
            h[0] = fill
        return np.zeros(err_dim)
    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, 1.0), [V(2)], err)


@pytest.mark.parametrize("err_dim, fill, match", [
    (3, np.eye(3), None),  # right shapes: the run goes through
    (2, np.eye(3)[:2], r"the error has shape \(2,\), the noise model dimension is 3"),
    (3, np.zeros((3, 6)), r"the Jacobian of v2 has shape \(3, 6\), expected \(3, 3\)"),
], ids=["right", "error length", "jacobian columns"])
def test_shapes_checked_before_gtsam(err_dim, fill, match):
    d = simulate("hill-drive", 1, duration_s=20.0)

    def ext(view):
        return Terms(factors=[_factor(err_dim, fill)])
    if match is None:
        est = GraphBatch(extensions=[ext]).run(d)
        assert est.info["extensions"] == {"ext": {"factors": 1, "variables": 0}}
        return
    with pytest.raises(ExtensionError, match=r"^graph extension 0 \(ext\): its factor on v2: "
                                             + match):
        GraphBatch(extensions=[ext]).run(d)
