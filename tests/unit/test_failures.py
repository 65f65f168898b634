"""Failures are data with a message that says something, in one schema for every document."""

from __future__ import annotations

import pytest

from vnav_graph.run import runner
from vnav_graph.simulation import simulate
from vnav_graph.util.failures import failure_message


def _raised(exc: BaseException) -> BaseException:
    try:
        raise exc
    except BaseException as caught:  # noqa: BLE001 - the test wants the traceback
        return caught


def test_message_is_the_first_non_blank_line() -> None:
    exc = _raised(ValueError("\n  \nsolver stalled\nat iteration 7"))
    assert failure_message(exc) == "solver stalled"
    assert failure_message(exc, typed=True) == "ValueError: solver stalled"


@pytest.mark.parametrize("exc", [RuntimeError(), RuntimeError(""), KeyError(""),
                                 RuntimeError("  \n ")])
def test_an_empty_message_names_the_type_and_the_place(exc: BaseException) -> None:
    caught = _raised(exc)
    for typed in (False, True):
        msg = failure_message(caught, typed=typed)
        kind = type(exc).__name__
        # KeyError('') prints as "''": a non-blank line, reported as it is
        if str(exc).strip():
            assert msg.endswith(str(exc).strip())
            continue
        assert msg.startswith(f"{kind} (no message; raised at test_failures.py:")
        assert not msg.endswith(": ") and "in _raised" in msg


def test_an_exception_never_raised_still_gets_a_message() -> None:
    assert failure_message(RuntimeError()) == "RuntimeError (no message)"


class _Silent:
    name = "silent"

    def run(self, drive):
        raise RuntimeError()


def test_an_estimator_failing_without_a_message_is_reported_with_its_type(monkeypatch) -> None:
    monkeypatch.setattr(runner, "create", lambda name, config=None: _Silent())
    drive = simulate("hill-drive", 1, duration_s=20.0)
    r = runner.run_one("silent", drive)
    assert r.estimate is None
    assert r.error.startswith("RuntimeError (no message; raised at test_failures.py:")
    assert r.runtime_s >= 0.0


def test_every_failed_block_has_the_summary_keys_with_null_metrics() -> None:
    base = runner.failed_block("RuntimeError: boom", 1.5)
    held = runner.holdout_failed("RuntimeError: boom", 1.5)
    assert set(base) < set(held)
    assert {k: held[k] for k in ("alt_offset_m", "n_scored", "per_window")} == {
        "alt_offset_m": None, "n_scored": 0, "per_window": []}
    for block in (base, held):
        assert block["status"] == "failed" and block["error"] == "RuntimeError: boom"
        assert block["runtime_s"] == 1.5
        metrics = [k for k in block if k.endswith(("_m", "_mps", "_deg", "_mean", "_dof"))]
        assert len(metrics) >= 8 and all(block[k] is None for k in metrics)
        assert all(p == {"est": None, "sd": None, "truth": None}
                   for p in block["baro"].values())


def test_unknown_names_are_refused_before_any_run() -> None:
    with pytest.raises(ValueError, match=r"unknown estimator\(s\) nope \(available: observer1d"):
        runner.resolve_estimators(["loop3", "nope"])
    assert runner.resolve_estimators(None) == runner.resolve_estimators([])
    assert "graph-batch" in runner.resolve_estimators(None)
