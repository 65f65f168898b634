"""The settings of benchmarks/isam2_relin_cost.py: what each variant changes."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import pytest

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.isam2.setup import isam2_params

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "isam2_relin_cost.py"
_spec = importlib.util.spec_from_file_location("isam2_relin_cost", _P)
rc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rc)


def _changed(cfg: GraphConfig) -> dict[str, object]:
    base = GraphConfig()
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)
            if getattr(cfg, f.name) != getattr(base, f.name)}


def test_default_is_graphconfig_as_shipped():
    assert _changed(rc.variant_config("default")) == {}


def test_coarse_scales_the_rotation_threshold_only():
    typed = GraphConfig().relinearize_typed
    changed = _changed(rc.variant_config("coarse"))
    assert list(changed) == ["relinearize_typed"]
    got = changed["relinearize_typed"]
    assert got[0] == pytest.approx(rc.COARSE * typed[0])
    assert tuple(got[1:]) == tuple(typed[1:])


def test_off_turns_relinearisation_off_in_isam2():
    cfg = rc.variant_config("off")
    assert _changed(cfg) == {"relinearize_threshold": 0.0}
    assert not isam2_params(cfg, robust=False).enableRelinearization
    assert isam2_params(GraphConfig(), robust=False).enableRelinearization
