"""Readers run quietly: captured output, and no file left open when the reader fails."""

from __future__ import annotations

import gc
import warnings

import pytest

from vnav_graph.io.quiet import quietly


def test_output_is_captured() -> None:
    def noisy() -> int:
        print("parser chatter")
        return 3

    result, cap = quietly(noisy)
    assert result == 3
    assert cap.count == 1 and "parser chatter" in cap.summary()


def test_a_failing_reader_leaves_no_open_file() -> None:
    def fails() -> None:
        print("half a line")
        raise ValueError("corrupt log")

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        with pytest.raises(ValueError, match="corrupt log"):
            quietly(fails)
        gc.collect()  # an unclosed capture file warns when collected
    assert not [w for w in rec if issubclass(w.category, ResourceWarning)]
