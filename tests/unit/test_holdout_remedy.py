"""``holdout.windows_remedy``: what would give a real log's holdout 4 windows, from the window
rule of ``holdout.choose_windows`` worked by hand."""

from __future__ import annotations

import numpy as np

from vnav_graph.evaluation.holdout import choose_windows, windows_remedy


def test_a_shorter_outage_that_gives_four_windows_is_named():
    t = np.arange(0.0, 400.0)  # 1 Hz GNSS, span 399 s: lead-in 60 s, last window ends ≤ 394 s
    # 60 s: spacing max(120, (399 − 60 − 60 − 5)/4) = 120 → starts 60, 180, 300: 3 windows
    assert len(choose_windows(t, 60.0)) == 3
    # 45 s: spacing max(90, 72.25) = 90 → starts 60, 150, 240, 330 (ends 375): 4 windows
    assert windows_remedy(t, 60.0, 3) == "--outage 45 gives 4 windows on this log"
    assert windows_remedy(t, 60.0, 4) is None  # enough already


def test_a_log_too_short_for_four_windows_says_so():
    t = np.arange(0.0, 61.0)  # span 60 s: lead-in 15 s; 10 s windows 20 s apart: 2 fit
    assert len(choose_windows(t, 10.0)) == 2
    assert windows_remedy(t, 60.0, 0) == ("this log's 60 s of GNSS holds fewer than 4 windows "
                                          "even of 10 s: a longer log would")


def test_run_picks_a_shorter_outage_only_where_60_s_gives_fewer_than_four():
    from vnav_graph.evaluation.holdout import auto_outage

    assert auto_outage(np.arange(0.0, 1200.0)) == (60.0, None)  # 60 s gives 5 windows
    t = np.arange(0.0, 400.0)  # 60 s gives 3 (above), 45 s gives 4
    assert auto_outage(t) == (45.0, "outage 45 s chosen: it gives 4 windows on this log "
                                    "where 60 s gives 3 (set --outage to choose)")
    assert auto_outage(np.arange(0.0, 61.0)) == (60.0, None)  # none gives 4: the default
