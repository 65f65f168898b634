"""Writers of the fuzz corpus: one simulated drive's plain arrays (``Raw``, ``sim_raw``) and
small writers that put them into every supported format (``.npz``, merged CSV, Sensor Logger
folder, ArduPilot DataFlash ``.bin``, PX4 ``.ulg``). ``corpus`` builds the damaged cases from
them."""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

G0 = 9.80665

# ------------------------------------------------------------------------ raw streams
@dataclass
class Raw:
    """Plain arrays of one drive in logger units (what a writer puts into a file)."""

    t_imu: np.ndarray  # s
    gyro: np.ndarray  # (N, 3) rad/s, FRD body
    acc: np.ndarray  # (N, 3) m/s², FRD body, gravity included
    t_gnss: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h: np.ndarray  # m
    vel_n: np.ndarray  # (M, 3) m/s NED
    sd_h: np.ndarray
    sd_v: np.ndarray
    t_baro: np.ndarray
    press: np.ndarray  # Pa
    baro_alt: np.ndarray  # m (ISA altitude of press)
    epoch_s: float = 1.75e9  # wall-clock start for formats that carry one
    # optional keys: "truth", "shuffle_records"; "mag" = (t [s], (K, 3) field [µT, FRD]),
    # written by write_dataflash (MAG, mG) and write_ulog (vehicle_magnetometer, Gauss)
    extra: dict[str, Any] = field(default_factory=dict)

    def copy(self) -> Raw:
        return Raw(**{k: (v.copy() if isinstance(v, np.ndarray) else v)
                      for k, v in self.__dict__.items() if k != "extra"},
                   extra=dict(self.extra))


def sim_raw(scenario: str = "hill-drive", duration_s: float = 120.0) -> tuple[Raw, Any]:
    """The simulated base: ``scenario`` (hill-drive: a car; sortie: an aircraft, which turns
    first at 180 s) seed 1, ``duration_s``, IMU decimated to 100 Hz."""
    from vnav_graph.geo.atmosphere import isa_pressure
    from vnav_graph.simulation import simulate

    d = simulate(scenario, 1, duration_s=duration_s)
    i = d.imu
    k = slice(None, None, 2)
    g, b = d.gnss, d.baro
    press = np.asarray(isa_pressure(b.altitude), dtype=float)
    raw = Raw(i.t[k] + 1.0, i.gyro_b[k], i.accel_b[k], g.t + 1.0, np.degrees(g.lla[:, 0]),
              np.degrees(g.lla[:, 1]), g.lla[:, 2].copy(), g.vel_n.copy(), g.pos_sd[:, 0].copy(),
              g.pos_sd[:, 2].copy(), b.t + 1.0, press, np.asarray(b.altitude, dtype=float))
    return raw, d


# ---------------------------------------------------------------------------- writers
def write_npz(raw: Raw, path: Path, drive: Any = None) -> Path:
    """The ``save_npz`` layout: the simulated Drive's truth, streams from ``raw``."""
    arrays, header = npz_arrays(raw, drive)
    return write_npz_arrays(arrays, header, path)


def npz_arrays(raw: Raw, drive: Any = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and JSON header ``save_npz`` would write, from raw streams (no validation,
    so hostile values reach the file)."""
    deg = np.pi / 180.0
    n = raw.t_gnss.size
    arrays = {
        "imu_t": raw.t_imu, "imu_gyro_b": raw.gyro, "imu_accel_b": raw.acc,
        "origin_lla": np.array([raw.lat_deg[0] * deg, raw.lon_deg[0] * deg, raw.h[0]]),
        "gnss_t": raw.t_gnss,
        "gnss_lla": np.column_stack([raw.lat_deg * deg, raw.lon_deg * deg, raw.h]),
        "gnss_pos_sd": np.column_stack([raw.sd_h, raw.sd_h, raw.sd_v]),
        "gnss_lever_arm_b": np.zeros(3), "gnss_vel_n": raw.vel_n,
        "gnss_vel_sd": np.full((n, 3), 0.1), "baro_t": raw.t_baro, "baro_alt": raw.baro_alt,
    }
    header: dict[str, Any] = {"format": "vnav_graph.drive/1",
                              "meta": {"name": "fuzz", "source": "log"},
                              "imu_spec": None, "gnss_spec": None, "baro_spec": None}
    if drive is not None and raw.extra.get("truth", True):
        tr = drive.truth
        keep = (tr.t + 1.0 >= raw.t_imu[0]) & (tr.t + 1.0 <= raw.t_imu[-1])
        arrays.update(truth_t=tr.t[keep] + 1.0, truth_lla=tr.lla[keep],
                      truth_vel_n=tr.vel_n[keep], truth_q_nb=tr.q_nb[keep])
        if tr.bias_baro is not None:
            arrays["truth_bias_baro"] = tr.bias_baro[keep]
        header["meta"]["source"] = "simulated"
        from dataclasses import asdict

        header["baro_truth"] = asdict(drive.baro_truth)
        from vnav_graph.io.drive_io import spec_to_json

        header["imu_spec"] = spec_to_json(drive.imu.spec)
        header["gnss_spec"] = spec_to_json(drive.gnss.spec)
        header["baro_spec"] = spec_to_json(drive.baro.spec)
    return arrays, header


def write_npz_arrays(arrays: dict[str, np.ndarray], header: Any, path: Path,
                     header_bytes: bytes | None = None) -> Path:
    out = dict(arrays)
    hb = header_bytes if header_bytes is not None else json.dumps(header).encode()
    out["header"] = np.frombuffer(hb, dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **out)
    return path


def write_merged_csv(raw: Raw, path: Path, time_style: str = "iso",
                     columns: dict[str, str] | None = None) -> Path:
    """1 s means of every stream, one row per second (the merged Sensor Logger layout).
    Phone axes: x_d = y_b, y_d = x_b, z_d = −z_b (flat phone, screen up)."""
    t0 = raw.t_imu[0]
    sec = np.floor(raw.t_imu - t0).astype(int)
    nrow = int(sec.max())
    rows = []

    def mean_at(t: np.ndarray, v: np.ndarray, a: float) -> np.ndarray:
        m = (t >= a) & (t < a + 1.0)
        if not m.any():
            j = int(np.clip(np.searchsorted(t, a), 0, t.size - 1))
            return v[j]
        return v[m].mean(axis=0)

    for k in range(nrow):
        a = t0 + k
        acc = mean_at(raw.t_imu, raw.acc, a)
        gyr = mean_at(raw.t_imu, raw.gyro, a)
        ad = (acc[1], acc[0], -acc[2])
        gd = (gyr[1], gyr[0], -gyr[2])
        j = int(np.clip(np.searchsorted(raw.t_gnss, a), 0, raw.t_gnss.size - 1))
        p = float(mean_at(raw.t_baro, raw.press, a))
        epoch = raw.epoch_s + k
        if time_style == "iso":
            import datetime as dt

            ts = dt.datetime.fromtimestamp(epoch, dt.UTC).strftime("%Y-%m-%d %H:%M:%S+00:00")
        elif time_style == "s":
            ts = f"{epoch:.0f}"
        elif time_style == "ms":
            ts = f"{epoch * 1e3:.0f}"
        elif time_style == "us":
            ts = f"{epoch * 1e6:.0f}"
        else:  # ns
            ts = f"{int(epoch) * 10**9}"
        rows.append([ts, raw.sd_v[j], raw.sd_h[j] * 1.5, raw.h[j], raw.lon_deg[j],
                     raw.lat_deg[j], ad[2], ad[1], ad[0], gd[2], gd[1], gd[0], p / 100.0])
    names = ["time", "verticalAccuracy", "horizontalAccuracy", "altitude", "longitude",
             "latitude", "acc_z", "acc_y", "acc_x", "gyro_z", "gyro_y", "gyro_x", "pressure"]
    if columns:
        names = [columns.get(n, n) for n in names]
    lines = [",".join(names)]
    for r in rows:
        lines.append(",".join([r[0]] + [repr(float(x)) for x in r[1:]]))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_sl_folder(raw: Raw, path: Path, skip: tuple[str, ...] = ()) -> Path:
    """Sensor Logger per-sensor CSV export (Android, standardised units)."""
    path.mkdir(parents=True, exist_ok=True)
    t0 = raw.t_imu[0]
    ns0 = int(raw.epoch_s) * 10**9

    def dump(name: str, t: np.ndarray, cols: dict[str, np.ndarray]) -> None:
        if name in skip:
            return
        out = io.StringIO()
        out.write("time,seconds_elapsed," + ",".join(cols) + "\n")
        mat = np.column_stack(list(cols.values()))
        for k in range(t.size):
            se = float(t[k] - t0)
            out.write(f"{ns0 + int(se * 1e9) if np.isfinite(se) else 0},{se!r},"
                      + ",".join(repr(float(x)) for x in mat[k]) + "\n")
        (path / f"{name}.csv").write_text(out.getvalue())

    acc, gyr = raw.acc, raw.gyro
    dump("AccelerometerUncalibrated", raw.t_imu,
         {"z": -acc[:, 2], "y": acc[:, 0], "x": acc[:, 1]})
    dump("GyroscopeUncalibrated", raw.t_imu, {"z": -gyr[:, 2], "y": gyr[:, 0], "x": gyr[:, 1]})
    dump("Location", raw.t_gnss, {"altitude": raw.h, "latitude": raw.lat_deg,
                                  "longitude": raw.lon_deg,
                                  "horizontalAccuracy": raw.sd_h * 1.5,
                                  "verticalAccuracy": raw.sd_v})
    dump("Barometer", raw.t_baro, {"relativeAltitude": raw.baro_alt - raw.baro_alt[0],
                                   "pressure": raw.press / 100.0})
    if "Metadata" not in skip:
        (path / "Metadata.csv").write_text(
            "version,device name,platform,standardisation\n3,fuzz phone,android,true\n")
    return path


# DataFlash: FMT(128) defines every other message; header 0xA3 0x95 <type>
_DF_STRUCT = {"B": "B", "H": "H", "I": "I", "f": "f", "L": "i", "Q": "Q", "n": "4s",
              "N": "16s", "Z": "64s", "b": "b", "h": "h", "i": "i", "d": "d", "q": "q"}
DF_MSGS = {
    "IMU": (130, "QffffffB", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,I"),
    "GPS": (131, "QBIHBfLLffffB", "TimeUS,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,I"),
    "BARO": (132, "QffffB", "TimeUS,Alt,Press,Temp,CRt,I"),
    "MAG": (133, "QhhhhhhhhhB", "TimeUS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ,I"),
}


def _df_fmt(type_id: int, name: str, fmt: str, cols: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_DF_STRUCT[c] for c in fmt))
    return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", type_id, length, name.encode(),
                                         fmt.encode(), cols.encode())


def write_dataflash(raw: Raw, path: Path, names: dict[str, str] | None = None) -> Path:
    """Minimal ArduPilot DataFlash log: FMT records, then IMU/GPS/BARO in time order.
    ``names`` renames messages in the FMT records only (the FMT-swap damage)."""
    names = names or {}
    out = [_df_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")]
    for name, (tid, fmt, cols) in DF_MSGS.items():
        if name != "MAG" or "mag" in raw.extra:  # the corpus files keep their 4 FMT records
            out.append(_df_fmt(tid, names.get(name, name), fmt, cols))
    recs: list[tuple[float, bytes]] = []

    def pack(name: str, *vals: Any) -> bytes:
        tid, fmt, _ = DF_MSGS[name]
        return b"\xa3\x95" + bytes([tid]) + struct.pack(
            "<" + "".join(_DF_STRUCT[c] for c in fmt), *vals)

    def us(t: float) -> int:
        return int(round(t * 1e6)) if np.isfinite(t) and t >= 0 else 0

    for k in range(raw.t_imu.size):
        recs.append((raw.t_imu[k], pack("IMU", us(raw.t_imu[k]), *raw.gyro[k], *raw.acc[k], 0)))
    gps_week, tow0 = 2360, 300_000.0
    for k in range(raw.t_gnss.size):
        v = raw.vel_n[k]
        spd = float(np.hypot(v[0], v[1]))
        crs = float(np.degrees(np.arctan2(v[1], v[0])) % 360.0)
        t = raw.t_gnss[k]
        recs.append((t, pack("GPS", us(t), 3, int((tow0 + (t if np.isfinite(t) else 0)) * 1e3)
                             % 2**32, gps_week, 10, raw.sd_h[k], _i32(raw.lat_deg[k] * 1e7),
                             _i32(raw.lon_deg[k] * 1e7), raw.h[k], spd, crs, v[2], 0)))
    for k in range(raw.t_baro.size):
        t = raw.t_baro[k]
        recs.append((t, pack("BARO", us(t), raw.baro_alt[k] - raw.baro_alt[0], raw.press[k],
                             20.0, 0.0, 0)))
    if "mag" in raw.extra:  # µT → int16 milligauss, offsets already applied (as ArduPilot)
        t_mag, b_ut = raw.extra["mag"]
        for k in range(len(t_mag)):
            mg = [int(np.clip(round(x * 10.0), -32768, 32767)) for x in b_ut[k]]
            recs.append((t_mag[k], pack("MAG", us(t_mag[k]), *mg, -36, 1, -56, 0, 0, 0, 0)))
    order = sorted(range(len(recs)), key=lambda j: (recs[j][0] if np.isfinite(recs[j][0])
                                                   else 0.0, j))
    if raw.extra.get("shuffle_records"):
        order = list(range(len(recs)))
    path.write_bytes(b"".join(out) + b"".join(recs[j][1] for j in order))
    return path


# DataFlash's scaled integer codes: struct code and scale (e: int32 x 100, c: int16 x 100, ...)
_DF_SCALED = {"e": ("i", 100), "E": ("I", 100), "c": ("h", 100), "C": ("H", 100),
              "L": ("i", 10**7), "M": ("B", 1)}


def dataflash_records(out: bytes | bytearray
                      ) -> Iterator[tuple[int, str, str, list[str], int]]:
    """The records of a DataFlash log other than FMT definitions, walked in order by the
    lengths their FMT records give (bytes that start no known record are skipped): (offset of
    the record's header, message name, format, column names, record length). ``out`` may be
    changed in place between records, as long as its length and FMT records stay."""
    fmts: dict[int, tuple[str, str, list[str], int]] = {}

    def text(b: bytes) -> str:
        return b.rstrip(b"\0").decode("ascii", "replace")

    i, n = 0, len(out)
    while i + 3 <= n:
        if out[i] != 0xA3 or out[i + 1] != 0x95:
            i += 1
            continue
        tid = out[i + 2]
        if tid == 0x80 and i + 89 <= n:
            t, length, name, fmt, cols = struct.unpack("<BB4s16s64s", bytes(out[i + 3:i + 89]))
            fmts[t] = (text(name), text(fmt), text(cols).split(","), length)
            i += 89
            continue
        if tid not in fmts:
            i += 1
            continue
        name, fmt, cols, length = fmts[tid]
        yield i, name, fmt, cols, length
        i += length


def dataflash_scale_field(data: bytes, msg: str, field_name: str, factor: float) -> bytes:
    """A DataFlash log with one numeric field of every ``msg`` record multiplied by
    ``factor`` (e.g. GPS ``Alt`` in feet; scaled integer fields are rounded), records walked
    by ``dataflash_records``; bytes that start no known record are copied as they are."""
    import numpy as np

    out = bytearray(data)
    for i, name, fmt, cols, _ in dataflash_records(out):
        if name == msg and field_name in cols:
            k = cols.index(field_name)
            off = i + 3 + struct.calcsize("<" + "".join(_DF_SCALED.get(c, ("", 1))[0]
                                                        or _DF_STRUCT[c] for c in fmt[:k]))
            code = _DF_SCALED[fmt[k]][0] if fmt[k] in _DF_SCALED else _DF_STRUCT[fmt[k]]
            (v,) = struct.unpack_from("<" + code, out, off)
            new = float(np.float32(v * factor)) if code in "fd" else int(round(v * factor))
            struct.pack_into("<" + code, out, off, new)
    return bytes(out)


def _i32(x: float) -> int:
    return int(np.clip(np.nan_to_num(x, nan=0.0), -2**31, 2**31 - 1))


def write_ulog(raw: Raw, path: Path, omit: tuple[str, ...] = ()) -> Path:
    """Minimal ULog v1 (header, flags, formats, subscriptions, data) in the layout PX4 uses
    (``ulog_bytes``); records in time order unless ``raw.extra["shuffle_records"]``."""

    def us(t: float) -> int:
        return int(round(t * 1e6)) if np.isfinite(t) and t >= 0 else 0

    topics: dict[str, tuple[str, list[tuple]]] = {
        "sensor_combined": ("uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
                            [(us(raw.t_imu[k]), *raw.gyro[k], *raw.acc[k])
                             for k in range(raw.t_imu.size)]),
        "vehicle_gps_position": (
            "uint64_t timestamp;int32_t lat;int32_t lon;int32_t alt;int32_t alt_ellipsoid;"
            "float eph;float epv;float s_variance_m_s;float vel_n_m_s;float vel_e_m_s;"
            "float vel_d_m_s;uint8_t vel_ned_valid;uint8_t fix_type;",
            [(us(raw.t_gnss[k]), _i32(raw.lat_deg[k] * 1e7), _i32(raw.lon_deg[k] * 1e7),
              _i32(raw.h[k] * 1e3), _i32(raw.h[k] * 1e3), raw.sd_h[k], raw.sd_v[k], 0.2,
              *raw.vel_n[k], 1, 3) for k in range(raw.t_gnss.size)]),
        "vehicle_air_data": ("uint64_t timestamp;float baro_pressure_pa;",
                             [(us(raw.t_baro[k]), raw.press[k]) for k in range(raw.t_baro.size)]),
    }
    if "mag" in raw.extra:  # µT → Gauss
        t_mag, b_ut = raw.extra["mag"]
        topics["vehicle_magnetometer"] = (
            "uint64_t timestamp;float[3] magnetometer_ga;",
            [(us(t_mag[k]), *(np.asarray(b_ut[k]) / 100.0)) for k in range(len(t_mag))])
    topics = {k: v for k, v in topics.items() if k not in omit}
    path.write_bytes(ulog_bytes(topics, in_time_order=not raw.extra.get("shuffle_records")))
    return path


def ulog_bytes(topics: dict[str, tuple[str, list[tuple]]], in_time_order: bool = True) -> bytes:
    """A minimal ULog v1 byte by byte (docs.px4.io "ULog File Format"): header, flag bits,
    formats, subscriptions, data (little endian). ``topics``: name → (format, rows), each
    row's first value its timestamp; the data records sorted by it (``in_time_order``) or
    topic by topic."""
    codes = {"uint64_t": "Q", "float": "f", "double": "d", "int32_t": "i", "uint8_t": "B",
             "int64_t": "q", "uint32_t": "I"}

    def msg(kind: bytes, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), kind[0]) + payload

    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)
    out += msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    for name, (fmt, _) in topics.items():
        out += msg(b"F", f"{name}:{fmt}".encode())
    for i, name in enumerate(topics):
        out += msg(b"A", struct.pack("<BH", 0, i) + name.encode())
    rows = []
    for i, (_, (fmt, data)) in enumerate(topics.items()):
        pack = "<"
        for member in fmt.strip(";").split(";"):
            typ = member.split(" ")[0]
            base, _, n = typ.partition("[")
            pack += (n.rstrip("]") if n else "") + codes[base]
        rows += [(r[0], i, struct.pack(pack, *r)) for r in data]
    if in_time_order:
        rows = sorted(rows, key=lambda x: x[0])
    for _, i, payload in rows:
        out += msg(b"D", struct.pack("<H", i) + payload)
    return out
