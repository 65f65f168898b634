"""'Did you mean' for misspelled names, where a name is looked up."""

from __future__ import annotations

import pytest

from vnav_graph.estimators.base import create
from vnav_graph.simulation import simulate
from vnav_graph.util.suggest import did_you_mean


def test_did_you_mean_closest_or_nothing():
    hint = did_you_mean("ekf-rst", ["ekf", "ekf-rts", "graph-batch"])
    assert hint == " (did you mean 'ekf-rts'?)"
    assert did_you_mean("zzzz", ["ekf", "ekf-rts"]) == ""


def test_names_looked_up_suggest_the_closest():
    with pytest.raises(ValueError, match=r"unknown scenario 'hil-drive' \(did you mean "
                                         r"'hill-drive'\?\)"):
        simulate("hil-drive", 0)
    with pytest.raises(ValueError, match=r"unknown estimator 'grapf-batch' \(did you mean "
                                         r"'graph-batch'\?\)"):
        create("grapf-batch")
