"""ArduPilot boot clock vs GPS time: the robust clock fit and the boot → GPS-seconds mapping
(closed forms on synthetic stamps), and the Erle PXF logs whose boot clock runs 7.7 % slow
(real-log tests skip when the shared data is absent)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.io.readers import read_log
from vnav_graph.io.readers._common import fit_clock, local_to_gps_seconds
from vnav_graph.io.readers.ardupilot import read_dataflash


# ------------------------------------------------------------------------- closed forms
def test_fit_clock_recovers_line_and_rejects_late_receipts() -> None:
    rng = np.random.default_rng(3)
    g = 471293.4 + np.arange(0.0, 360.0, 0.2)  # GPS time of week, 5 Hz
    ratio, offset = 12.0 / 13.0, 72.334
    jitter = rng.uniform(-0.02, 0.02, g.size)  # ±20 ms receipt jitter, sd 0.02/√3
    late = np.zeros(g.size)
    late[::97] = 0.5  # a busy logger stamps some fixes 0.5 s late
    t_local = offset + ratio * (g - g[0]) + jitter + late
    fit = fit_clock(t_local, g)
    # 1800 stamps with sd 11.5 ms over a 360 s lever arm: slope sd ≈ 11.5e-3/(360/√12)/√1800
    # = 2.6e-6, intercept sd ≈ 2·11.5e-3/√1800 = 5e-4; tolerances are 4 sd
    assert fit.ratio == pytest.approx(ratio, abs=1e-5)
    assert fit.offset == pytest.approx(offset, abs=2e-3)
    assert fit.n_outliers == late.astype(bool).sum()
    assert fit.sd == pytest.approx(0.04 / np.sqrt(12), rel=0.1)  # uniform sd, 1800 samples
    np.testing.assert_allclose(fit.local_of_gps(g), offset + ratio * (g - g[0]), atol=3e-3)
    with pytest.raises(ValueError, match="do not follow GPS time"):
        fit_clock(rng.uniform(0, 100, 20), np.arange(20.0))


def test_local_to_gps_seconds_closed_form() -> None:
    r, t_ref = 0.92315, 72.464
    t_boot = np.array([t_ref, t_ref + 0.02, t_ref + 335.0])
    t = local_to_gps_seconds(t_boot, r, t_ref)
    # t = t_ref + (t_boot − t_ref)/r: t_ref is a fixed point, 20 ms boot → 21.665 ms GPS
    assert t[0] == t_ref
    assert t[1] - t[0] == pytest.approx(0.02 / r, rel=1e-12)
    assert t[2] - t[0] == pytest.approx(335.0 / r, rel=1e-12)  # ≈ 362.9 s
    # GNSS stamps on the boot clock (fitted line) become GPS time + one constant
    g = np.arange(0.0, 100.0, 0.2)
    off = 72.33
    t_g = local_to_gps_seconds(off + r * g, r, t_ref)
    np.testing.assert_allclose(t_g - g, t_ref + (off - t_ref) / r, atol=1e-9)
    # r = 1 is the identity
    np.testing.assert_array_equal(local_to_gps_seconds(t_boot, 1.0, t_ref), t_boot)


# ---------------------------------------------------------------------------- real logs
def test_erle_218_boot_clock_ratio_and_gps_time(shared_log: Callable[[str], Path]) -> None:
    path = shared_log("erle_pxf_218/218.BIN")
    d = read_log(path)
    c = d.meta["clock"]
    # GPS time spans 363.0 s while boot time spans 335.0 s: 0.9229; the fit over all fixes
    # gives 0.92315. ±0.002 covers the fit (jitter sd 7.6 ms over 363 s → slope sd 1e-6)
    # and the span-based estimate's ±0.1 s end effects
    assert c["boot_clock_per_gps_second"] == pytest.approx(0.923, abs=2e-3)
    assert c["basis"].startswith("GPS time")
    r = c["boot_clock_per_gps_second"]
    # GNSS stamps follow GPS time of week (one constant apart): the fixes are 0.2 s apart in
    # GPS time (a few logged 199/201 ms epochs: 0.005 of a step), so stamp differences are
    # multiples of 0.2 s within 0.01 step; on the boot clock they would be 0.923 steps
    steps = np.diff(d.gnss.t)
    np.testing.assert_allclose(steps / 0.2, np.round(steps / 0.2), atol=0.01)
    assert d.gnss.t[-1] - d.gnss.t[0] == pytest.approx(363.0, abs=0.2)  # GPS-time span
    # IMU, baro: boot stamps rescaled by 1/r about the first IMU stamp
    raw = read_dataflash(path, clock="boot")
    assert raw.meta["clock"]["basis"].startswith("autopilot boot")
    t_ref = raw.imu.t[0]
    np.testing.assert_allclose(d.imu.t, t_ref + (raw.imu.t - t_ref) / r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(d.baro.t, t_ref + (raw.baro.t - t_ref) / r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(d.gnss.t, t_ref + (raw.gnss.t - t_ref) / r, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(d.imu.gyro_b, raw.imu.gyro_b)  # values untouched
    # IMU median step: 20 ms boot = 21.67 ms GPS (46.2 Hz)
    assert np.median(np.diff(d.imu.t)) == pytest.approx(0.020 / r, rel=1e-3)
    # evidence: receiver velocity integrates to its own displacement on GPS time (1.02,
    # within the 5 % of a 5-fix window of u-blox positions), not on boot time (1.10 = 1.02/r)
    ev = c["evidence"]
    assert ev["displacement_over_speed_integral_gps_clock"] == pytest.approx(1.0, abs=0.05)
    # boot-clock windows are 1/r shorter up to the receiver's 199/201 ms epochs (±0.5 %)
    assert ev["displacement_over_speed_integral_boot_clock"] == pytest.approx(
        ev["displacement_over_speed_integral_gps_clock"] / r, rel=5e-3)
    with pytest.raises(ValueError, match="clock must be"):
        read_dataflash(path, clock="utc")
