"""Lossless save/load of a Drive as a compressed ``.npz`` (arrays + one JSON header).

Arrays per stream: ``imu_*``, ``gnss_*``, ``baro_*``, ``truth_*`` and, when the drive has a
magnetometer, ``mag_t`` [s] and ``mag_field_b`` (N, 3) [µT, body FRD] with the header field
``mag_sd_ut`` [µT]. A file without ``mag_t`` (all files written before the magnetometer)
reads with ``Drive.mag = None``.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BaroSpec, GnssSpec, ImuSpec
from ..types import BaroTruth, Drive, Trajectory
from ..types.streams import EVENT_STREAMS, BaroStream, GnssStream, ImuStream, MagStream
from ..util.failures import failure_message

FORMAT = "vnav_graph.drive/1"
STORED_STREAMS = ("gnss", "baro", "mag")  # the Drive's optional streams a drive file keeps
_SPECS = {"ImuSpec": ImuSpec, "GnssSpec": GnssSpec, "BaroSpec": BaroSpec}


def spec_to_json(spec: Any) -> Any:
    if spec is None:
        return None
    if is_dataclass(spec) and type(spec).__name__ in _SPECS:
        return {"type": type(spec).__name__, "fields": asdict(spec)}
    raise ValueError(f"cannot serialise sensor spec of type {type(spec).__name__}")


def _tuplify(v: Any) -> Any:
    return tuple(_tuplify(x) for x in v) if isinstance(v, list) else v


def _spec_from_json(d: Any) -> Any:
    if d is None:
        return None
    cls = _SPECS[d["type"]]
    names = {f.name for f in fields(cls)}
    return cls(**{k: _tuplify(v) for k, v in d["fields"].items() if k in names})


def save_npz(drive: Drive, path: str | Path) -> Path:
    """Write ``drive`` to ``path`` (.npz). Floats are stored as float64: lossless."""
    p = Path(path)
    lost = [n for n in EVENT_STREAMS if n not in STORED_STREAMS and getattr(drive, n) is not None]
    if lost:  # never write a file that reads back without a stream
        raise ValueError(f"drive.{lost[0]}: a drive file (.npz) does not store this stream")
    arrays: dict[str, np.ndarray] = {
        "imu_t": drive.imu.t, "imu_gyro_b": drive.imu.gyro_b, "imu_accel_b": drive.imu.accel_b,
        "origin_lla": drive.origin_lla,
    }
    header: dict[str, Any] = {
        "format": FORMAT, "meta": dict(drive.meta), "imu_spec": spec_to_json(drive.imu.spec),
    }
    if drive.gnss is not None:
        g = drive.gnss
        arrays.update(gnss_t=g.t, gnss_lla=g.lla, gnss_pos_sd=g.pos_sd,
                      gnss_lever_arm_b=g.lever_arm_b)
        if g.vel_n is not None:
            arrays.update(gnss_vel_n=g.vel_n, gnss_vel_sd=g.vel_sd)
        header["gnss_spec"] = spec_to_json(g.spec)
    if drive.baro is not None:
        b = drive.baro
        arrays["baro_t"] = b.t
        if b.pressure is not None:
            arrays["baro_pressure"] = b.pressure
        if b.alt is not None:
            arrays["baro_alt"] = b.alt
        header["baro_spec"] = spec_to_json(b.spec)
    if drive.mag is not None:
        arrays.update(mag_t=drive.mag.t, mag_field_b=drive.mag.field_b)
        header["mag_sd_ut"] = drive.mag.sd_ut
    if drive.truth is not None:
        tr = drive.truth
        for f in ("t", "lla", "vel_n", "q_nb", "bias_gyro", "bias_accel", "bias_baro"):
            v = getattr(tr, f)
            if v is not None:
                arrays[f"truth_{f}"] = v
    if drive.baro_truth is not None:
        header["baro_truth"] = asdict(drive.baro_truth)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    tmp = p.with_name(p.name + ".part")
    with open(tmp, "wb") as fh:  # write then rename: nothing half-written under the real name
        np.savez_compressed(fh, **arrays)
    tmp.replace(p)
    return p


# An .npz is a zip of .npy members; every member is checked against the zip directory
# before anything is decompressed (a 3.5 MB crafted file once expanded to 1.26 GB).
# A 3-hour 200 Hz drive with truth is ~350 MB uncompressed at a ratio of 1.5-3 (noisy float64
# barely compresses); constant columns compress ~150x but are small.
MAX_NPZ_BYTES = 4 * 1024**3  # total uncompressed size [bytes], refused outright
LARGE_NPZ_BYTES = 256 * 1024**2  # above this, the overall ratio must stay below MAX_NPZ_RATIO
MAX_NPZ_RATIO = 50.0
_ARRAY_KEYS_FLOAT = {
    "imu_t", "imu_gyro_b", "imu_accel_b", "origin_lla", "gnss_t", "gnss_lla", "gnss_pos_sd",
    "gnss_lever_arm_b", "gnss_vel_n", "gnss_vel_sd", "baro_t", "baro_pressure", "baro_alt",
    "truth_t", "truth_lla", "truth_vel_n", "truth_q_nb", "truth_bias_gyro", "truth_bias_accel",
    "truth_bias_baro", "mag_t", "mag_field_b",
}
_TIME_KEYS = {"imu_t", "gnss_t", "baro_t", "truth_t", "mag_t"}


def _check_zip_directory(p: Path) -> None:
    """Reject an archive whose declared member sizes are implausible, before decompressing."""
    try:
        with zipfile.ZipFile(p) as zf:
            infos = zf.infolist()
    except (OSError, zipfile.BadZipFile, ValueError, EOFError) as exc:
        raise ValueError(f"{p.name}: not a readable .npz drive ({exc})") from None
    total = sum(i.file_size for i in infos)
    packed = max(1, sum(i.compress_size for i in infos))
    if total > MAX_NPZ_BYTES or (total > LARGE_NPZ_BYTES and total / packed > MAX_NPZ_RATIO):
        raise ValueError(f"{p.name}: .npz declares {total / 1e6:.0f} MB uncompressed from "
                         f"{packed / 1e6:.1f} MB (ratio {total / packed:.0f}): corrupt or "
                         "hostile archive, not read")


def _numeric(name: str, a: np.ndarray, fname: str) -> np.ndarray:
    """float64 copy of a stored array; ValueError on a non-numeric or integer-time dtype."""
    if a.dtype.kind not in "fiu" or a.dtype == np.bool_:
        raise ValueError(f"{fname}: array {name!r} has dtype {a.dtype}, expected float64 "
                         "(corrupt or hand-edited drive)")
    if name in _TIME_KEYS and a.dtype.kind in "iu":
        raise ValueError(f"{fname}: array {name!r} has integer dtype {a.dtype}; time stamps "
                         "must be float seconds (milliseconds or microseconds stored?)")
    return np.asarray(a, dtype=np.float64)


def _header_dict(header: Any, key: str, fname: str) -> dict[str, Any] | None:
    v = header.get(key)
    if v is None:
        return None
    if not isinstance(v, dict):
        raise ValueError(f"{fname}: header field {key!r} is a {type(v).__name__}, expected an "
                         "object")
    return v


def _spec_checked(d: Any, key: str, fname: str) -> Any:
    """Sensor spec from the header; ValueError naming the field on a malformed entry."""
    if d is None:
        return None
    if not isinstance(d, dict) or d.get("type") not in _SPECS or not isinstance(
            d.get("fields"), dict):
        raise ValueError(f"{fname}: header {key!r} is not a sensor spec "
                         "({'type': ImuSpec|GnssSpec|BaroSpec, 'fields': {...}})")
    cls = _SPECS[d["type"]]
    for f in fields(cls):
        v = d["fields"].get(f.name)
        if v is None or f.name not in d["fields"]:
            continue
        numeric = isinstance(f.default, float) or f.type in ("float", "float | None")
        if numeric and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise ValueError(f"{fname}: header {key!r} field {f.name!r} is "
                             f"{type(v).__name__} {v!r}, expected a number")
        if str(f.type).startswith("tuple") and not isinstance(v, list):
            raise ValueError(f"{fname}: header {key!r} field {f.name!r} is "
                             f"{type(v).__name__}, expected a list")
    try:
        return _spec_from_json(d)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{fname}: header {key!r} has an invalid field "
                         f"({failure_message(exc)})") from None


def _mag_checked(a: dict[str, np.ndarray], header: dict[str, Any],
                 fname: str) -> MagStream | None:
    """Magnetometer from ``mag_t`` [s], ``mag_field_b`` [µT] and header ``mag_sd_ut`` [µT]
    (absent: MagStream's default); None when the file has no ``mag_t``."""
    if "mag_t" not in a:
        return None
    sd = header.get("mag_sd_ut", 1.0)
    if isinstance(sd, bool) or not isinstance(sd, (int, float)):
        raise ValueError(f"{fname}: header 'mag_sd_ut' is {type(sd).__name__} {sd!r}, "
                         "expected a number of µT")
    return MagStream(a["mag_t"], a["mag_field_b"], float(sd))


def _imu_units_first(a: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """Convert ``imu_gyro_b`` / ``imu_accel_b`` in place where ``io.imu_units.unit_fixes``
    finds deg/s or g units, before ``ImuStream``'s range check sees them (counted in
    ``meta["repaired"]["imu"]``, warned in ``meta["warnings"]``). Arrays of the wrong shape
    are left for ``ImuStream`` to refuse."""
    from .imu_units import unit_fixes

    t, w, f = a.get("imu_t"), a.get("imu_gyro_b"), a.get("imu_accel_b")
    if t is None or w is None or f is None or t.ndim != 1 or w.shape != (t.size, 3) \
            or f.shape != (t.size, 3):
        return
    for fix in unit_fixes(t, w, f):
        key = "imu_gyro_b" if fix.field == "gyro" else "imu_accel_b"
        a[key] = a[key] * fix.factor
        rep = meta.get("repaired") if isinstance(meta.get("repaired"), dict) else {}
        imu = dict(rep.get("imu") or {}) if isinstance(rep.get("imu"), dict) else {}
        imu[fix.reason] = imu.get(fix.reason, 0) + int(t.size)
        meta["repaired"] = {**rep, "imu": imu}
        meta["warnings"] = [*list(meta.get("warnings") or []), fix.warning]


def load_npz(path: str | Path) -> Drive:
    """Read a Drive written by ``save_npz``. ValueError on a corrupt or foreign file.

    Checks, in order: the zip directory (sizes, before decompressing), each member's
    decompression and CRC, the JSON header's structure and types (``meta`` must be an object:
    null or missing is refused, as ``save_npz`` never writes either), every array's dtype
    (numeric; float seconds for time stamps), then the stream types' own validation. A file
    whose truth arrays are all absent reads as a real drive (``baro_truth`` dropped too;
    ``meta["notes"]`` says so).
    """
    p = Path(path)
    _check_zip_directory(p)
    try:
        with np.load(p, allow_pickle=False) as z:  # known members only: nothing else inflated
            raw = {k: z[k] for k in z.files if k in _ARRAY_KEYS_FLOAT or k == "header"}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
        raise ValueError(f"{p.name}: not a readable .npz drive ({failure_message(exc)})"
                         ) from None
    if "header" not in raw:
        raise ValueError(f"{p.name}: .npz without a vnav_graph header")
    try:
        header = json.loads(raw["header"].tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError):
        raise ValueError(f"{p.name}: corrupt header") from None
    if not isinstance(header, dict):
        raise ValueError(f"{p.name}: corrupt header (not a JSON object)")
    if header.get("format") != FORMAT:
        raise ValueError(f"{p.name}: unsupported format {header.get('format')!r}")
    a = {k: _numeric(k, v, p.name) for k, v in raw.items() if k in _ARRAY_KEYS_FLOAT}
    if header.get("meta") is None:  # save_npz always writes an object (possibly empty)
        raise ValueError(f"{p.name}: header field 'meta' is "
                         f"{'null' if 'meta' in header else 'missing'}, expected an object "
                         "(corrupt or hand-edited drive; an empty drive writes {})")
    meta = dict(_header_dict(header, "meta", p.name) or {})
    _imu_units_first(a, meta)
    try:
        imu = ImuStream(a["imu_t"], a["imu_gyro_b"], a["imu_accel_b"],
                        _spec_checked(header.get("imu_spec"), "imu_spec", p.name))
        gnss = None
        if "gnss_t" in a:
            gnss = GnssStream(a["gnss_t"], a["gnss_lla"], a["gnss_pos_sd"], a.get("gnss_vel_n"),
                              a.get("gnss_vel_sd"), a["gnss_lever_arm_b"],
                              _spec_checked(header.get("gnss_spec"), "gnss_spec", p.name))
        baro = None
        if "baro_t" in a:
            baro = BaroStream(a["baro_t"], a.get("baro_pressure"), a.get("baro_alt"),
                              _spec_checked(header.get("baro_spec"), "baro_spec", p.name))
        mag = _mag_checked(a, header, p.name)
        truth = None
        truth_keys = sorted(k for k in raw if k.startswith("truth_"))
        if truth_keys:
            truth = Trajectory(a["truth_t"], a["truth_lla"], a["truth_vel_n"], a.get("truth_q_nb"),
                               a.get("truth_bias_gyro"), a.get("truth_bias_accel"),
                               a.get("truth_bias_baro"))
        bt_doc = _header_dict(header, "baro_truth", p.name)
        baro_truth = None
        if truth is None:
            if meta.get("source") == "simulated" or bt_doc is not None:
                notes = list(meta.get("notes") or [])
                notes.append("no truth arrays in the file: read as a real drive (errors are "
                             "scored against withheld GNSS)")
                meta["notes"] = notes
                meta["source"] = "log"
        elif bt_doc is not None:
            try:
                baro_truth = BaroTruth(scale=float(bt_doc["scale"]),
                                       latency_s=float(bt_doc["latency_s"]))
            except (KeyError, TypeError, ValueError):
                raise ValueError(f"{p.name}: header 'baro_truth' needs numeric 'scale' and "
                                 "'latency_s'") from None
        return Drive(imu, gnss, baro, a["origin_lla"], truth, baro_truth, meta, mag)
    except KeyError as exc:
        raise ValueError(f"{p.name}: missing array {exc.args[0]!r}") from None
