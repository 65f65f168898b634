"""The estimator registry: every docs/design.md name maps to the estimator of that name, lazily."""

from __future__ import annotations

import subprocess
import sys

import pytest

from vnav_graph.estimators.base import available, create, register

DESIGN_NAMES = ["observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7", "ekf",
                "ekf-rts", "graph-isam2", "graph-batch"]


def test_every_design_name_creates_the_estimator_of_that_name() -> None:
    assert available()[:len(DESIGN_NAMES)] == DESIGN_NAMES
    for name in DESIGN_NAMES:
        # a registry entry pointing at the wrong class (e.g. ekf -> EKFRTS) fails here
        assert create(name).name == name


def test_unknown_and_missing_modules() -> None:
    with pytest.raises(ValueError, match="unknown estimator 'nope'"):
        create("nope")
    from vnav_graph.estimators.base import registry_snapshot

    with registry_snapshot():
        register("not-built", "vnav_graph.estimators.no_such_module:X")
        assert "not-built" not in available()


def test_listing_imports_no_estimator_module() -> None:
    """``available()`` (``vnav-graph list``) must not import gtsam, numba or the estimators."""
    code = ("import sys\nfrom vnav_graph.estimators.base import available\nnames = available()\n"
            "heavy = [m for m in ('gtsam', 'numba', 'scipy', 'vnav_graph.estimators.ekf.filter')"
            " if m in sys.modules]\nprint(len(names), heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split(maxsplit=1)
    assert int(out[0]) >= len(DESIGN_NAMES)
    assert out[1].strip() == "[]"


def test_list_says_what_each_estimator_and_scenario_is(capsys):
    from vnav_graph.cli import main
    from vnav_graph.estimators.base import DESCRIPTIONS, available
    from vnav_graph.simulation import list_scenarios, scenario_description

    assert main(["list"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = {ln.split()[0]: ln.split(None, 1)[1] for ln in out if ln.startswith("  ")}
    for name in available():
        assert rows[name] == DESCRIPTIONS[name]
    for s in list_scenarios():
        assert rows[s] == scenario_description(s) and rows[s]
