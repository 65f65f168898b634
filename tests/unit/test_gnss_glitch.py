"""GNSS position glitches (``nav.gnss_glitch``): out-and-back blocks are found, lasting shifts
and ordinary motion are not; the causal rule decides each fix from the fixes up to it."""

from __future__ import annotations

import numpy as np

from vnav_graph.nav.gnss_glitch import (
    MAX_GLITCH_S,
    MAX_SPEED,
    causal_glitch_mask,
    glitch_mask,
)

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


def _glitched(rng: np.random.Generator) -> np.ndarray:
    """A track with three separate out-and-back glitches of 20 m … 10 km, 0.1 … 20 s (one
    in each 40 s third of the drive)."""
    p = _track(rng.uniform(0.0, 40.0))[:, :2]
    for third in range(3):
        a = 400 * third + int(rng.integers(1, 190))
        n = int(rng.integers(1, 200))
        x = rng.uniform(0.0, 2 * np.pi)
        p[a:a + n] += rng.uniform(20.0, 1e4) * np.array([np.cos(x), np.sin(x)])
    return p


def test_the_causal_rule_equals_the_whole_drive_one_on_out_and_back_glitches() -> None:
    """Glitches that return inside MAX_GLITCH_S with a jump faster than MAX_SPEED: the causal
    rule refuses the same fixes as ``glitch_mask`` (200 random drives)."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        p = _glitched(rng)
        assert np.array_equal(causal_glitch_mask(T, p), glitch_mask(T, p))


def test_the_causal_rule_decides_each_fix_from_the_fixes_up_to_it() -> None:
    """Cut the fixes anywhere: the decisions on the fixes before the cut do not change (the
    whole-drive rule's do: inside a glitch it keeps the fixes until the return is seen)."""
    rng = np.random.default_rng(4)
    p = _glitched(rng)
    full = causal_glitch_mask(T, p)
    changed_whole = 0
    for n in range(2, T.size, 7):
        assert np.array_equal(causal_glitch_mask(T[:n], p[:n]), full[:n])
        changed_whole += not np.array_equal(glitch_mask(T[:n], p[:n]), glitch_mask(T, p)[:n])
    assert changed_whole > 0


def test_the_causal_rule_refuses_the_first_max_s_of_a_lasting_shift() -> None:
    """A 500 m shift that never comes back: refused for MAX_GLITCH_S, then taken (the
    whole-drive rule, which sees there is no return, refuses none)."""
    p = _track()[:, :2]
    p[T >= 30.0] += 500.0
    got = causal_glitch_mask(T, p)
    assert not glitch_mask(T, p).any()
    # the shift leaves from the fix at 29.9 s: open until MAX_GLITCH_S after it
    held = (T >= 30.0) & (T - 29.9 <= MAX_GLITCH_S + 1e-9)
    np.testing.assert_array_equal(np.flatnonzero(got), np.flatnonzero(held))
