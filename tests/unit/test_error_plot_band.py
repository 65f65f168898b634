"""The ±3σ band of the altitude-error panels: clipped to the axis, pale and noted when it
fills the panel (a real log's filters report σ of tens of metres against errors of one)."""

from __future__ import annotations

import numpy as np

from vnav_graph.report.error_plots import plot_altitude_errors
from vnav_graph.report.errors import TRUTH, ErrorSeries, ErrorSet
from vnav_graph.report.panels import SIGMA_NOTE_ABOVE, band_overflow, sigma_inside


def test_band_overflow_counts_samples_beyond_the_axis():
    sd = np.array([0.1, 1.0, 2.0, np.nan])
    assert band_overflow(sd, 2.0) == 2 / 3  # 3σ = 3 and 6 exceed ±2
    assert band_overflow(np.full(3, np.nan), 1.0) == 0.0


def test_a_band_wider_than_the_axis_is_noted():
    t = np.linspace(0.0, 100.0, 501)
    err = 0.5 * np.sin(t / 5.0)
    tight = ErrorSeries("ekf-rts", t, err, np.full(t.size, 0.1), None)  # 3σ inside
    wide = ErrorSeries("ekf", t, err, np.full(t.size, 20.0), None)
    plot = plot_altitude_errors(ErrorSet(TRUTH, [tight, wide], [(40.0, 60.0)], False),
                                {"ekf-rts": 0.35, "ekf": 0.35}, "test")
    assert plot is not None
    wide_notes = [n for n in plot.notes if n.startswith("ekf: ±3σ beyond the axis")]
    assert len(wide_notes) == 1 and "100 % of the time (median 3σ 60 m)" in wide_notes[0]
    assert not any(n.startswith("ekf-rts: ±3σ") for n in plot.notes)
    assert SIGMA_NOTE_ABOVE < 1.0


def test_sigma_line_stops_at_the_axis():
    """3σ inside ±lim is drawn as is; beyond it (and where σ is unknown) it is not drawn,
    so the line never runs along the panel's edge."""
    line = sigma_inside(np.array([0.1, 0.5, 1.0, np.nan]), 2.0)
    np.testing.assert_allclose(line[:2], [0.3, 1.5])
    assert np.isnan(line[2:]).all()
    np.testing.assert_array_equal(sigma_inside(np.array([1.0]), 2.0, k=1.0), [1.0])
