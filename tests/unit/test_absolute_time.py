"""The drive's absolute time (``meta["t0_unix_s"]``, used for UTC stamps in the GPX export):
GPS → UTC conversion against known dates, and the readers on the shared logs against the
log's own time columns."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np
import pandas as pd
import pytest

from vnav_graph.io import load_drive
from vnav_graph.io.readers._common import gps_to_unix, t0_unix_meta


def _unix(*ymdhms):
    return datetime(*ymdhms, tzinfo=UTC).timestamp()


@pytest.mark.parametrize("week, tow, utc, leap", [
    (2086, 0.0, (2019, 12, 29), 18),     # after the 2017 leap second
    (1930, 86400.0, (2017, 1, 2), 18),
    (1825, 0.0, (2014, 12, 28), 16),     # 2012-07 .. 2015-06: 16 s
    (1357, 0.0, (2006, 1, 8), 14),
])
def test_gps_to_unix_known_dates(week, tow, utc, leap):
    gps = week * 604800.0 + tow
    assert gps_to_unix(gps) == pytest.approx(_unix(*utc) - leap, abs=1e-6)


def test_t0_unix_meta_median_and_plausibility():
    t = np.arange(0.0, 10.0, 0.5)
    u = 1.7e9 + 3.25 + t + np.r_[0.02, np.zeros(t.size - 1)]  # one jittered stamp
    assert t0_unix_meta(u, t) == {"t0_unix_s": pytest.approx(1.7e9 + 3.25)}
    assert t0_unix_meta(t + 500.0, t) == {}  # not a Unix time
    assert t0_unix_meta(np.zeros_like(t), t) == {}  # receivers' 0 before a fix


def test_sensorlogger_folder_t0_from_location_time(data_dir):
    folder = data_dir / "ski_iphone_100hz"
    if not folder.is_dir():
        pytest.skip("ski_iphone_100hz not in the shared data")
    loc = pd.read_csv(folder / "Location.csv")
    expect = np.median(loc["time"].to_numpy() * 1e-9 - loc["seconds_elapsed"].to_numpy())
    assert load_drive(folder).meta["t0_unix_s"] == pytest.approx(expect, abs=1e-3)


def test_dataflash_t0_is_the_flight_date(data_dir):
    log = data_dir / "erle_pxf_218" / "218.BIN"
    if not log.is_file():
        pytest.skip("218.BIN not in the shared data")
    d = load_drive(log)
    start = datetime.fromtimestamp(d.meta["t0_unix_s"] + d.gnss.t[0], UTC)
    # the log's decimal year (from the GPS week) and the UTC date agree to a day
    year = start.year + (start - datetime(start.year, 1, 1, tzinfo=UTC)).days / 365.0
    assert year == pytest.approx(d.meta["decimal_year"], abs=1 / 365.0)
