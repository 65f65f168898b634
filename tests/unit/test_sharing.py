"""One computation shared by the estimators of a run, its time charged to each reuser."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
import pytest

from vnav_graph.estimators.vertical import ahrs_cache as sharing
from vnav_graph.estimators.vertical import inputs
from vnav_graph.run import runner


@dataclass
class _Result:
    values: np.ndarray


def _slow(calls: list[int], value: float = 1.0):
    def compute() -> _Result:
        calls.append(1)
        time.sleep(0.05)
        warnings.warn("shared warning", RuntimeWarning, stacklevel=1)
        return _Result(np.full(3, value))

    return compute


def test_outside_a_block_nothing_is_shared() -> None:
    calls: list[int] = []
    drive = object()
    with pytest.warns(RuntimeWarning):
        a = sharing.shared_call("x", drive, 1, _slow(calls))
    with pytest.warns(RuntimeWarning):
        b = sharing.shared_call("x", drive, 1, _slow(calls))
    assert len(calls) == 2 and a is not b
    a.values[0] = 5.0  # not frozen either


def test_a_block_computes_once_per_drive_and_config_and_charges_each_reuse() -> None:
    calls: list[int] = []
    d1, d2 = object(), object()
    with sharing.sharing() as box:
        with pytest.warns(RuntimeWarning, match="shared warning"):
            first = sharing.shared_call("x", d1, 1, _slow(calls))
        assert box.take() == 0.0  # the first caller paid in its own wall time
        with pytest.warns(RuntimeWarning, match="shared warning"):  # replayed to the reuser
            again = sharing.shared_call("x", d1, 1, _slow(calls))
        assert again is first and len(calls) == 1
        charged = box.take()
        assert 0.05 <= charged < 1.0
        assert box.take() == 0.0
        with pytest.raises(ValueError, match="read-only"):
            first.values[0] = 2.0
        with pytest.warns(RuntimeWarning):
            sharing.shared_call("x", d1, 2, _slow(calls))  # other config
        with pytest.warns(RuntimeWarning):
            sharing.shared_call("x", d2, 1, _slow(calls))  # other drive
        with pytest.warns(RuntimeWarning):
            sharing.shared_call("y", d1, 1, _slow(calls))  # other computation
        assert len(calls) == 4 and box.hits == 1
    with pytest.warns(RuntimeWarning):
        sharing.shared_call("x", d1, 1, _slow(calls))  # the block is over
    assert len(calls) == 5


def test_the_vertical_filters_of_a_run_share_one_ahrs_and_each_is_charged_for_it(
        monkeypatch) -> None:
    from vnav_graph.simulation import simulate

    drive = simulate("default", 0, duration_s=30.0)
    real = inputs.compute_vertical_inputs
    seconds: list[float] = []

    def counted(drive, cfg):
        vi = real(drive, cfg)
        seconds.append(vi.runtime_s)
        return vi

    monkeypatch.setattr(inputs, "compute_vertical_inputs", counted)
    alone = runner.run_one("loop3", drive)
    assert len(seconds) == 1
    out = runner.run_estimators(drive, ["loop2", "loop3", "vkf4"], progress=False,
                                  prewarm=None)
    assert len(seconds) == 2  # one AHRS for the three filters of the run
    assert all(r.estimate is not None for r in out)
    # the same numbers as a run of its own, and a runtime that includes the AHRS it reused
    np.testing.assert_array_equal(out[1].estimate.trajectory.alt, alone.estimate.trajectory.alt)
    assert out[1].runtime_s >= seconds[1]
    assert out[2].runtime_s >= seconds[1]
