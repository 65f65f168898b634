"""The PX4 reader on the two real ULogs of the shared data (pyulog's BSD test files).

Values below were measured on these
files and cross-checked by hand: Trondheim (63.42 N) and Zurich (47.40 N) fields, ellipsoidal
GNSS heights, Pa from vehicle_air_data, a stationary or hovering vehicle (|f| ≈ g).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vnav_graph.io import load_drive
from vnav_graph.io.readers import detect_format

DEG = np.pi / 180.0


@pytest.mark.parametrize(("name", "n_imu", "rate_hz", "n_gnss", "n_baro", "lat", "lon", "h"), [
    ("sample_log_small", 1298, 204.6, 32, 120, 63.4171, 10.4082, 106.8),
    ("sample_px4_events", 7783, 250.0, 22, 623, 47.3977, 8.5456, 488.0),
])
def test_real_ulog(data_dir: Path, name, n_imu, rate_hz, n_gnss, n_baro, lat, lon, h):
    p = data_dir / "px4_ulog_samples" / f"{name}.ulg"
    assert detect_format(p) == "px4-ulog"
    d = load_drive(p)
    assert (len(d.imu), len(d.gnss), len(d.baro)) == (n_imu, n_gnss, n_baro)
    assert d.imu.rate_hz == pytest.approx(rate_hz, abs=0.1)
    np.testing.assert_allclose(d.origin_lla[:2] / DEG, [lat, lon], atol=1e-4)
    assert d.origin_lla[2] == pytest.approx(h, abs=0.1)
    assert d.meta["height_reference"] == "ellipsoid"
    # a level vehicle at rest or hovering reads about (0, 0, -g) in FRD
    f = np.median(d.imu.accel_b, axis=0)
    assert f[2] < -9.0 and np.hypot(f[0], f[1]) < 1.5
    assert 9e4 < np.median(d.baro.pressure) < 1.02e5  # Pa, not hPa
    assert d.gnss.vel_n is not None and "onboard" in d.meta


def test_real_ulog_events_reports_fixes_without_3d(data_dir: Path):
    d = load_drive(data_dir / "px4_ulog_samples" / "sample_px4_events.ulg")
    assert d.meta["dropped"]["gnss"] == {"no 3-D fix (fix_type < 3)": 9}
    assert any("9 of 31" in w for w in d.meta["warnings"])
