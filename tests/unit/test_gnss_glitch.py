"""GNSS position glitches (``nav.gnss_glitch``): out-and-back blocks are found, lasting shifts
and ordinary motion are not."""

from __future__ import annotations

import numpy as np

from vnav_graph.nav.gnss_glitch import MAX_GLITCH_S, MAX_SPEED, glitch_mask

T = np.arange(0.0, 120.0, 0.1)  # 10 Hz fixes


def _track(speed: float = 30.0) -> np.ndarray:
    """A straight drive east at ``speed`` m/s (N, E, D)."""
    return np.column_stack([np.zeros_like(T), speed * T, np.zeros_like(T)])


def test_a_held_10_km_jump_is_one_block() -> None:
    p = _track()
    m = (T >= 60.0) & (T < 65.0)
    p[m, 0] += 10_000.0
    got = glitch_mask(T, p[:, :2])
    assert np.array_equal(got, m) and got.sum() == 50


def test_an_isolated_spike_and_max_fixes() -> None:
    p = _track()
    p[300, 2] -= 500.0  # one fix 500 m up: 5 km/s in and out
    assert np.flatnonzero(glitch_mask(T, p)).tolist() == [300]
    p[600:610, 2] -= 500.0  # a 1 s block of wrong heights
    assert np.flatnonzero(glitch_mask(T, p, max_fixes=1)).tolist() == [300]
    assert glitch_mask(T, p).sum() == 11


def test_a_lasting_shift_and_clean_motion_are_not_glitches() -> None:
    p = _track(MAX_SPEED * 0.9)  # fast but possible
    assert not glitch_mask(T, p).any()
    p[600:, 0] += 5_000.0  # jumps and stays: which side is right is unknown
    assert not glitch_mask(T, p).any()
    q = _track()
    long = (T >= 10.0) & (T < 10.0 + MAX_GLITCH_S + 1.0)  # back after more than max_s
    q[long, 0] += 5_000.0
    assert not glitch_mask(T, q).any()


def test_nan_rows_are_skipped() -> None:
    p = _track()
    p[100:110, 0] += 10_000.0
    p[105] = np.nan
    got = glitch_mask(T, p)
    assert got.sum() == 9 and not got[105]
