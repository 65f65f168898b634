"""graph-isam2 retries a pass with its robust settings on a failed update (``UpdateFailed``)
and on nothing else, whatever the message says."""

from __future__ import annotations

import pytest

from vnav_graph.estimators.graph.isam2 import smoother as sm
from vnav_graph.estimators.graph.isam2.setup import UpdateFailed
from vnav_graph.estimators.graph.settings import GraphConfig
from vnav_graph.simulation import simulate


@pytest.fixture(scope="module")
def drive():
    return simulate("hill-drive", seed=0, duration_s=30.0)


def _patched(monkeypatch, first: BaseException, calls: list):
    def fake_run(self, drive, cfg, robust, t_start, fallback):
        calls.append((robust, fallback))
        if not robust:
            raise first
        return "retried"

    monkeypatch.setattr(sm.GraphISAM2, "_run", fake_run)
    monkeypatch.setattr(sm, "checked", lambda est, *a, **k: est)


def test_a_failed_update_is_retried_with_the_robust_settings(monkeypatch, drive):
    calls: list = []
    _patched(monkeypatch, UpdateFailed("diverged at keyframe 3"), calls)
    assert sm.GraphISAM2(GraphConfig(gnss_gm_auto=False)).run(drive) == "retried"
    assert calls == [(False, None), (True, "diverged at keyframe 3")]


def test_another_error_is_named_and_not_retried_even_with_the_prefix(monkeypatch, drive):
    calls: list = []
    _patched(monkeypatch, RuntimeError("graph-isam2: looks like an update, is not"), calls)
    with pytest.raises(RuntimeError, match=r"^graph-isam2: graph-isam2: looks like") as info:
        sm.GraphISAM2(GraphConfig(gnss_gm_auto=False)).run(drive)
    assert not isinstance(info.value, UpdateFailed)
    assert calls == [(False, None)]
