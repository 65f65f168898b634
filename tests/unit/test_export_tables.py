"""``export.tables``: rows at the output rate (taken, not interpolated), the CSV's degrees and
side file, and the one-line summary of skipped files."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from vnav_graph.export import EXPORT_RATE_HZ, ExportResult
from vnav_graph.export.tables import (
    at_rate,
    column_meaning,
    column_unit,
    csv_metadata,
    csv_name,
    csv_table,
)
from vnav_graph.types import SD_COLUMNS, Estimate, Trajectory


def _table(t: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t_s": t, "k": np.arange(t.size)})


def test_export_rate_is_the_graph_output_rate():
    from vnav_graph.estimators.graph.settings import GraphConfig

    assert GraphConfig().output_rate_hz == EXPORT_RATE_HZ == 20.0


@pytest.mark.parametrize("dt, step", [(0.005, 0.05), (0.05, 0.05), (0.02, 0.1),
                                      (0.2, 0.2), (1.0, 1.0)])
def test_at_rate_keeps_the_epochs_on_the_20_hz_grid(dt, step):
    """Tracks of 240 s at 200, 20, 50, 5 and 1 Hz (clock values k·dt with rounding noise)
    keep their epochs at multiples of 0.05 s: every 0.05 s, or every 0.1 s for the 50 Hz
    track, which has no epoch at 0.05 s. Each exported track's rows are rows of the truth's
    export (evo and a spreadsheet pair them by time stamp)."""
    t = np.arange(0, round(240 / dt) + 1) * dt
    out = at_rate(_table(t), EXPORT_RATE_HZ)
    n = round(240 / step) + 1
    assert len(out) == n
    np.testing.assert_allclose(out["t_s"], np.arange(n) * step, rtol=0, atol=1e-9)
    # rows are taken: each kept row is the input row of that time, index and all
    np.testing.assert_array_equal(out["t_s"], t[out["k"]])
    truth = at_rate(_table(np.arange(0, 48001) * 0.005), EXPORT_RATE_HZ)["t_s"].to_numpy()
    j = np.searchsorted(truth, out["t_s"].to_numpy() - 1e-9)
    np.testing.assert_allclose(truth[j], out["t_s"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("dt, every", [(0.00995, {5}), (0.0199, {3}), (0.0497, {1}),
                                       (0.0025, {19, 20})])
def test_a_track_off_the_grid_is_thinned_to_0_0475_s(dt, every):
    """A log's own clock (a phone's 100 Hz filter and its 50 Hz ekf, a 20 Hz output on that
    clock, a 400 Hz autopilot; 0.2 % jitter, starting off the grid) seldom lies on the grid:
    its first epoch, then each first epoch at least 0.0475 s after the last row."""
    rng = np.random.default_rng(1)
    n = round(60.0 / dt)
    t = 0.0123 + np.arange(n) * dt + rng.uniform(-1e-3, 1e-3, n) * dt
    out = at_rate(_table(t), EXPORT_RATE_HZ)
    want = [0]
    for i in range(1, n):  # the rule, written out
        if t[i] - t[want[-1]] >= 0.0475:
            want.append(i)
    np.testing.assert_array_equal(out["k"], want)
    assert set(np.diff(out["k"])) == every  # 19 × 0.0025 s is 0.0475 s: jitter decides


def test_at_rate_leaves_slower_or_irregular_tracks_and_full_rate_alone():
    slow = _table(np.array([0.0, 0.7, 1.0, 2.3, 2.31, 5.0]))  # 2.3 and 2.31 share an interval
    assert at_rate(slow, EXPORT_RATE_HZ)["t_s"].tolist() == [0.0, 0.7, 1.0, 2.3, 5.0]
    fast = _table(np.arange(0, 1001) * 0.005)
    assert at_rate(fast, None) is fast


def test_csv_angles_in_degrees_other_columns_unchanged():
    lat, yaw, gyro = np.radians(47.123456789), np.radians(-170.0), np.radians(0.01)
    df = pd.DataFrame({"t_s": [1.0], "lat_rad": [lat], "alt_m": [512.5], "yaw_rad": [yaw],
                       "bias_gyro_x_radps": [gyro], "att_d_sd_rad": [np.radians(2.0)],
                       "vel_n_mps": [3.0], "baro_scale": [0.01]})
    out = csv_table(df)
    assert list(out.columns) == ["t_s", "lat_deg", "alt_m", "yaw_deg", "bias_gyro_x_degps",
                                 "att_d_sd_deg", "vel_n_mps", "baro_scale"]
    np.testing.assert_allclose(out.iloc[0].to_numpy(),
                               [1.0, 47.123456789, 512.5, -170.0, 0.01, 2.0, 3.0, 0.01],
                               rtol=1e-14)


def _full_estimate() -> Estimate:
    t = np.arange(0.0, 2.01, 0.5)
    n = t.size
    lla = np.column_stack([np.full(n, 0.8), np.full(n, 0.2), np.full(n, 500.0)])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    tr = Trajectory(t, lla, np.zeros((n, 3)), q, np.zeros((n, 3)), np.zeros((n, 3)),
                    np.zeros(n))
    return Estimate("ekf", tr, {"alt", "vel_d", "pos_h", "vel_h", "att", "baro", "cov"},
                    cov=np.tile(np.eye(18), (n, 1, 1)), t_cov=t, origin_lla=lla[0])


def test_every_column_of_a_full_table_has_a_unit_and_a_meaning():
    """The side file describes each column the estimates can have: a unit from its suffix and
    a meaning that is not the bare name."""
    cols = [csv_name(c) for c in _full_estimate().to_dataframe().columns]
    assert {csv_name(c) for c in SD_COLUMNS} <= set(cols)
    for c in cols:
        assert column_meaning(c, "height above the WGS-84 ellipsoid") != c, c
        want = "1" if c in ("baro_scale", "baro_scale_sd") else c.rsplit("_", 1)[1]
        unit = {"degps": "deg/s", "mps": "m/s", "mps2": "m/s^2"}.get(want, want)
        assert column_unit(c) == unit, c
    assert column_meaning("mystery_column", "") == "mystery_column"


def test_csv_metadata_is_csv_on_the_web():
    meta = csv_metadata("ekf.online.csv", ["t_s", "lat_deg", "yaw_sd_deg"], "ekf (online)",
                        "online", ["drive: x"], "vnav_graph 0", "height above the ellipsoid")
    json.dumps(meta)  # serialisable
    assert meta["@context"] == "http://www.w3.org/ns/csvw" and meta["url"] == "ekf.online.csv"
    assert meta["dialect"]["headerRowCount"] == 1
    assert meta["dc:description"].startswith("online (real-time) estimate")
    cols = meta["tableSchema"]["columns"]
    assert [c["name"] for c in cols] == ["t_s", "lat_deg", "yaw_sd_deg"]
    assert [c["schema:unitText"] for c in cols] == ["s", "deg", "deg"]


def test_skipped_files_are_one_line_grouped_by_reason():
    res = ExportResult()
    assert res.skipped_line() is None
    vert = "vertical-only estimate (no horizontal track): CSV only"
    for fmt in ("kml", "gpx", "tum"):
        for name in ("vkf4", "loop2", "loop3", "observer1d", "vekf7", "loop3-adaptive"):
            res.skipped.append((name, fmt, vert))
    res.skipped.append(("mine", "tum", "no attitude: no TUM pose"))
    line = res.skipped_line()
    assert "\n" not in line
    assert line == ("kml, gpx, tum of loop2, loop3, loop3-adaptive, observer1d, vekf7, vkf4: "
                    f"{vert}; tum of mine: no attitude: no TUM pose")


def test_export_help_states_the_rate():
    import contextlib
    import io

    from vnav_graph.cli import build_parser

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
        build_parser().parse_args(["export", "--help"])
    text = " ".join(buf.getvalue().split())
    assert f"{EXPORT_RATE_HZ:g} Hz grid" in text and f"{1 / EXPORT_RATE_HZ:g} s" in text
