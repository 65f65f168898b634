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


def test_a_progress_announcement_during_a_quiet_read_reaches_the_terminal() -> None:
    """``run`` announces a slow read ("vnav-graph: reading LOG ...") from a timer thread while
    the reader's output is captured: the line goes to the terminal and is not counted as a
    parsing-library message (it was the only 'suppressed message' of a run on 218.BIN)."""
    import subprocess
    import sys

    code = ("import time\n"
            "from vnav_graph.io.quiet import quietly\n"
            "from vnav_graph.run.progress import stage\n"
            "with stage('reading x', 'lines', announce_after_s=0.05):\n"
            "    _, cap = quietly(time.sleep, 0.4)\n"
            "print(cap.count, cap.examples)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "0 []"
    assert "vnav-graph: reading x ..." in r.stderr
    assert "vnav-graph: reading x: done in" in r.stderr
