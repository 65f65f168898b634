"""Lossless save/load of a Drive as a compressed ``.npz`` (arrays + one JSON header)."""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BaroSpec, GnssSpec, ImuSpec
from ..types import BaroStream, BaroTruth, Drive, GnssStream, ImuStream, Trajectory

FORMAT = "vnav_graph.drive/1"
_SPECS = {"ImuSpec": ImuSpec, "GnssSpec": GnssSpec, "BaroSpec": BaroSpec}


def _spec_to_json(spec: Any) -> Any:
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
    arrays: dict[str, np.ndarray] = {
        "imu_t": drive.imu.t, "imu_gyro_b": drive.imu.gyro_b, "imu_accel_b": drive.imu.accel_b,
        "origin_lla": drive.origin_lla,
    }
    header: dict[str, Any] = {
        "format": FORMAT, "meta": dict(drive.meta), "imu_spec": _spec_to_json(drive.imu.spec),
    }
    if drive.gnss is not None:
        g = drive.gnss
        arrays.update(gnss_t=g.t, gnss_lla=g.lla, gnss_pos_sd=g.pos_sd,
                      gnss_lever_arm_b=g.lever_arm_b)
        if g.vel_n is not None:
            arrays.update(gnss_vel_n=g.vel_n, gnss_vel_sd=g.vel_sd)
        header["gnss_spec"] = _spec_to_json(g.spec)
    if drive.baro is not None:
        b = drive.baro
        arrays["baro_t"] = b.t
        if b.pressure is not None:
            arrays["baro_pressure"] = b.pressure
        if b.alt is not None:
            arrays["baro_alt"] = b.alt
        header["baro_spec"] = _spec_to_json(b.spec)
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


def load_npz(path: str | Path) -> Drive:
    """Read a Drive written by ``save_npz``. ValueError on a corrupt or foreign file."""
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"{p.name}: not a readable .npz drive ({exc})") from None
    if "header" not in a:
        raise ValueError(f"{p.name}: .npz without a vnav_graph header")
    try:
        header = json.loads(a["header"].tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise ValueError(f"{p.name}: corrupt header") from None
    if header.get("format") != FORMAT:
        raise ValueError(f"{p.name}: unsupported format {header.get('format')!r}")
    try:
        imu = ImuStream(a["imu_t"], a["imu_gyro_b"], a["imu_accel_b"],
                        _spec_from_json(header.get("imu_spec")))
        gnss = None
        if "gnss_t" in a:
            gnss = GnssStream(a["gnss_t"], a["gnss_lla"], a["gnss_pos_sd"], a.get("gnss_vel_n"),
                              a.get("gnss_vel_sd"), a["gnss_lever_arm_b"],
                              _spec_from_json(header.get("gnss_spec")))
        baro = None
        if "baro_t" in a:
            baro = BaroStream(a["baro_t"], a.get("baro_pressure"), a.get("baro_alt"),
                              _spec_from_json(header.get("baro_spec")))
        truth = None
        if "truth_t" in a:
            truth = Trajectory(a["truth_t"], a["truth_lla"], a["truth_vel_n"], a.get("truth_q_nb"),
                               a.get("truth_bias_gyro"), a.get("truth_bias_accel"),
                               a.get("truth_bias_baro"))
        bt = header.get("baro_truth")
        return Drive(imu, gnss, baro, a["origin_lla"], truth,
                     None if bt is None else BaroTruth(**bt), header.get("meta", {}))
    except KeyError as exc:
        raise ValueError(f"{p.name}: missing array {exc.args[0]!r}") from None
