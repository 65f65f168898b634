"""Drive save/load is lossless; corrupt files give a clean ValueError."""

import numpy as np
import pytest

from vnav_graph.io import load_drive, save_npz
from vnav_graph.simulation import simulate


def test_npz_round_trip_is_lossless(tmp_path):
    d = simulate("sortie", 4, duration_s=30.0)
    p = save_npz(d, tmp_path / "d.npz")
    e = load_drive(p)
    for a, b in [(d.imu.t, e.imu.t), (d.imu.gyro_b, e.imu.gyro_b), (d.gnss.lla, e.gnss.lla),
                 (d.gnss.vel_n, e.gnss.vel_n), (d.baro.alt, e.baro.alt),
                 (d.truth.q_nb, e.truth.q_nb), (d.truth.bias_baro, e.truth.bias_baro)]:
        np.testing.assert_array_equal(a, b)
    assert e.imu.spec == d.imu.spec and e.gnss.spec == d.gnss.spec
    assert e.baro.spec == d.baro.spec and e.baro_truth == d.baro_truth
    # load_drive adds only the sanity checks' statistics; a clean drive gets no warning
    assert {k: v for k, v in e.meta.items() if k != "sanity"} == dict(d.meta)
    assert "warnings" not in e.meta and "imu_rotation_stats" in e.meta["sanity"]


def test_corrupt_and_truncated_files(tmp_path):
    d = simulate("hill-drive", 1, duration_s=10.0)
    p = save_npz(d, tmp_path / "d.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(ValueError, match="cut.npz"):
        load_drive(cut)
    with pytest.raises(ValueError, match="no such file"):
        load_drive(tmp_path / "missing.npz")
