"""Zeroed and garbage halves of a log file are reported with their size and place
(``io.tails``), for the corpus writers' DataFlash, ULog, merged CSV and Sensor Logger files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tests.fuzz.corpus import (
    sim_raw,
    write_dataflash,
    write_merged_csv,
    write_sl_folder,
    write_ulog,
)
from vnav_graph.io import load_drive
from vnav_graph.io.tails import MIN_BYTES, garbage_stretches

RAW, _ = sim_raw()
WRITE = {"dataflash": (write_dataflash, ".bin"), "ulog": (write_ulog, ".ulg"),
         "merged-csv": (write_merged_csv, ".csv")}


def _tail_warnings(d) -> list[str]:
    return [w for w in d.meta.get("warnings") or [] if "of the file are" in w]


@pytest.mark.parametrize("fmt", sorted(WRITE))
def test_a_zeroed_second_half_is_reported_with_size_and_read_time(tmp_path, fmt):
    fn, suffix = WRITE[fmt]
    p = fn(RAW, tmp_path / f"log{suffix}")
    b = p.read_bytes()
    assert garbage_stretches(p) == []  # the intact file
    n = len(b) // 2
    p.write_bytes(b[:n] + bytes(len(b) - n))
    d = load_drive(p)
    g = d.meta["garbage"]
    assert len(g) == 1 and g[0]["kind"] == "zero bytes"
    # the run may start a few bytes early where the data end in zeros (binary fields)
    assert 0 <= g[0]["bytes"] - (len(b) - n) < 64 and g[0]["file_bytes"] == len(b)
    w = _tail_warnings(d)
    assert len(w) == 1, d.meta["warnings"]
    m = re.fullmatch(rf"log{re.escape(suffix)}: the last (\d+) kB \(50 %\) of the file are zero "
                     r"bytes: data read up to ([\d.]+) s into the drive", w[0])
    assert m is not None, w[0]
    assert int(m.group(1)) == round((len(b) - n) / 1024)
    span = max(s.t[-1] for s in (d.imu, d.gnss, d.baro)) - min(s.t[0] for s in (d.imu, d.gnss,
                                                                               d.baro))
    assert float(m.group(2)) == pytest.approx(span, abs=0.05)
    assert 55.0 < span < 62.0  # half of the 120 s drive was read


@pytest.mark.parametrize("fmt", ["dataflash", "merged-csv", "ulog"])
def test_a_random_second_half_is_unparsable_bytes(tmp_path, fmt):
    fn, suffix = WRITE[fmt]
    p = fn(RAW, tmp_path / f"log{suffix}")
    b = p.read_bytes()
    n = len(b) // 2
    noise = np.random.default_rng(3).integers(0, 256, len(b) - n, dtype=np.uint8).tobytes()
    p.write_bytes(b[:n] + noise)
    found = garbage_stretches(p)
    assert len(found) == 1 and found[0].kind == "unparsable bytes" and found[0].is_tail
    # at the last line before the noise, or a record's length (256 bytes) past the last
    # DataFlash header
    assert abs(n - found[0].start) < 300


def test_a_zeroed_sensor_logger_csv_is_named(tmp_path):
    folder = write_sl_folder(RAW, tmp_path / "sl")
    f = folder / "AccelerometerUncalibrated.csv"
    b = f.read_bytes()
    f.write_bytes(b[: len(b) // 2] + bytes(len(b) - len(b) // 2))
    w = _tail_warnings(load_drive(folder))
    assert len(w) == 1 and w[0].startswith("AccelerometerUncalibrated.csv: the last 506 kB")


def test_small_zero_runs_are_not_reported(tmp_path):
    p = write_dataflash(RAW, tmp_path / "log.bin")
    b = bytearray(p.read_bytes())
    k = len(b) // 3
    b[k:k + MIN_BYTES - 1] = bytes(MIN_BYTES - 1)  # one byte short of a file-system block
    p.write_bytes(bytes(b))
    assert [s for s in garbage_stretches(p) if s.kind == "zero bytes"] == []
    b[k:k + MIN_BYTES + 1000] = bytes(MIN_BYTES + 1000)  # 0.9 % of the file: below 2 %
    p.write_bytes(bytes(b))
    assert [s for s in garbage_stretches(p) if s.kind == "zero bytes"] == []


def test_shared_logs_have_no_garbage(data_dir: Path):
    files = [p for p in sorted(data_dir.glob("*/*")) if p.suffix.lower() in (".bin", ".ulg",
                                                                               ".csv")]
    assert len(files) >= 10
    for p in files:
        assert garbage_stretches(p) == [], p.name


@pytest.mark.parametrize("fmt", ["dataflash", "ulog"])
def test_a_noise_block_inside_a_binary_log_is_placed(tmp_path, fmt):
    """20 % of the file overwritten in the middle: one stretch, placed to within a record or
    message (the readers resume after it)."""
    fn, suffix = WRITE[fmt]
    p = fn(RAW, tmp_path / f"log{suffix}")
    b = p.read_bytes()
    a, n = int(0.4 * len(b)), int(0.2 * len(b))
    noise = np.random.default_rng(5).integers(0, 256, n, dtype=np.uint8).tobytes()
    p.write_bytes(b[:a] + noise + b[a + n:])
    found = garbage_stretches(p)
    assert len(found) == 1 and not found[0].is_tail, found
    assert abs(found[0].start - a) < 300 and abs(found[0].length - n) < 600
    m = re.fullmatch(rf"log{re.escape(suffix)}: (\d+) kB \(20 %\) of unparsable bytes from "
                     r"byte (\d+) \(40 % into the file\)", found[0].text(None))
    assert m is not None, found[0].text(None)
    assert abs(int(m.group(1)) - n / 1024) < 1.5 and abs(int(m.group(2)) - a) < 300


@pytest.mark.parametrize("log", ["erle_pxf_218/218.BIN", "px4_ulog_samples/sample_log_small.ulg",
                                 "car_phone_1hz_2025-03-01a/2025-03-01_15-04-26.csv"])
def test_shared_logs_with_a_zeroed_second_half(data_dir, tmp_path, log):
    src = data_dir / log
    if not src.exists():
        pytest.skip(f"{log} not present")
    b = src.read_bytes()
    n = len(b) // 2
    p = tmp_path / src.name
    p.write_bytes(b[:n] + bytes(len(b) - n))
    found = garbage_stretches(p)
    assert len(found) == 1 and found[0].kind == "zero bytes" and found[0].is_tail
    assert 0 <= found[0].length - (len(b) - n) < 128
    d = load_drive(p)  # measured: 218 read up to 179.9 s, the car drive to 2729 s
    assert any(w.startswith(f"{src.name}: the last ") and "(50 %) of the file are zero bytes: "
               "data read up to" in w for w in d.meta["warnings"]), d.meta["warnings"]
