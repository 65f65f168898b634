"""Seeded corpus of corrupted and hostile inputs for every supported format.

Nothing here is committed as data: every case is written at test time from

- a **simulated drive** (``hill-drive``, seed 1, 120 s; and a ``sortie`` aircraft, 400 s, for
  the gyro-axis damage), written by the small writers of
  ``writers`` in all five formats: ``.npz`` (``save_npz``), ArduPilot DataFlash ``.bin``,
  PX4 ``.ulg``, a Sensor Logger CSV folder and a merged 1 Hz CSV;
- the **small real cuts in tests/data** (always present);
- the **shared real logs** (``$VNAV_DATA`` or ``../shared/data``; those cases are left out when
  the folder is absent).

Case families
-------------
- ``control``: the base itself (undamaged).
- ``bytes``: truncations, byte flips, swapped / duplicated / zeroed blocks, header damage,
  applied to the file bytes (for a folder: to one of its CSVs).
- ``semantic``: the streams are changed before writing: units (g, deg/s, feet, ms, hPa), axis
  swaps, NaN / inf, constant or zero streams, every value of the second half zeroed, shuffled
  stamps, a long IMU gap.
- ``hostile``: well-formed but physically hostile streams: accelerometer or gyro clipping,
  baro steps and spikes, GNSS jumps.
- ``structure``: format-specific damage: ``.npz`` keys, dtypes and JSON header; CSV columns,
  field counts, time encodings; DataFlash FMT records; missing Sensor Logger files.

Every case has a stable id ``format/base/family/mutation``; the same seed always gives the
same bytes. The damage itself is in ``mutations``, the writers in ``writers``.
"""

from __future__ import annotations

import io
import os
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .mutations import (
    HEADER_LEN,
    SEMANTIC,
    byte_mutations,
    csv_text_mutations,
    df_patch_field,
    df_patch_fmt_names,
    df_scale_fields,
    imu_gap,
    npz_structure,
)
from .writers import (
    Raw,
    npz_arrays,
    sim_raw,
    write_dataflash,
    write_merged_csv,
    write_npz,
    write_npz_arrays,
    write_sl_folder,
    write_ulog,
)

SEED = 20261128
REPO = Path(__file__).resolve().parents[2]
TEST_DATA = REPO / "tests" / "data"


def shared_data_dir() -> Path | None:
    env = os.environ.get("VNAV_DATA")
    for cand in ([Path(env)] if env else []) + [REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    return None




WRITERS: dict[str, Callable[..., Path]] = {
    "npz": write_npz, "dataflash": write_dataflash, "ulog": write_ulog,
    "sl-folder": write_sl_folder, "merged-csv": write_merged_csv,
}
SUFFIX = {"npz": ".npz", "dataflash": ".bin", "ulog": ".ulg", "sl-folder": "",
          "merged-csv": ".csv"}


# ----------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class Case:
    """One corpus entry. ``build(dir)`` writes it into an empty directory and returns the
    path to load; ``control`` names the undamaged case it is compared with."""

    id: str
    fmt: str
    family: str
    damaged: bool
    build: Callable[[Path], Path]
    control: str | None = None


def _bytes_case(cid: str, fmt: str, src: Callable[[Path], Path], mut: Callable[..., bytes],
                seed: int, control: str, member: str | None = None) -> Case:
    def build(d: Path) -> Path:
        p = src(d / "src")
        if p.is_dir():
            files = sorted(p.glob("*.csv"))
            f = next((x for x in files if member and x.stem == member), files[seed % len(files)])
            f.write_bytes(mut(f.read_bytes(), np.random.default_rng(seed)))
            return p
        out = d / ("case" + p.suffix)
        out.write_bytes(mut(p.read_bytes(), np.random.default_rng(seed)))
        return out
    return Case(cid, fmt, "bytes", True, build, control)


def _copy_src(src: Path) -> Callable[[Path], Path]:
    def build(d: Path) -> Path:
        d.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            dst = d / src.name
            shutil.copytree(src, dst)
            return dst
        dst = d / src.name
        shutil.copyfile(src, dst)
        return dst
    return build


def _swap_csv_columns(text: str, a: str, b: str) -> str:
    """A CSV's header with columns ``a`` and ``b`` renamed into each other (their values
    swap places)."""
    head, _, body = text.partition("\n")
    cols = [{a: b, b: a}.get(c.strip(), c) for c in head.split(",")]
    return ",".join(cols) + "\n" + body


def build_cases(include_shared: bool = True) -> list[Case]:
    """Every case of the corpus (deterministic order and content)."""
    raw, sim = sim_raw()
    cases: list[Case] = []
    rng = np.random.default_rng(SEED)

    def sim_writer(fmt: str, r: Raw, **kw: Any) -> Callable[[Path], Path]:
        def build(d: Path) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            p = d / ("sim" + SUFFIX[fmt])
            if fmt == "npz":
                return write_npz(r, p, sim)
            return WRITERS[fmt](r, p, **kw)
        return build

    # ---- simulated base in every format: control, semantic, hostile, bytes
    for fmt in WRITERS:
        ctrl = f"{fmt}/sim/control/none"
        cases.append(Case(ctrl, fmt, "control", False, sim_writer(fmt, raw), ctrl))
        for name, (mut, fam, only) in SEMANTIC.items():
            if only is not None and fmt not in only:
                continue
            r = mut(raw, np.random.default_rng(int(rng.integers(2**31))))
            cases.append(Case(f"{fmt}/sim/{fam}/{name}", fmt, fam, True, sim_writer(fmt, r),
                              ctrl))
        hl = HEADER_LEN.get(fmt, 0)
        for name, mut in byte_mutations(hl).items():
            cases.append(_bytes_case(f"{fmt}/sim/bytes/{name}", fmt, sim_writer(fmt, raw), mut,
                                     int(rng.integers(2**31)), ctrl))

    # ---- a base that is not a car (sortie: an aircraft, 400 s, banked turns from 180 s): the
    # gyro-axis damage, which the ground-vehicle checks do not see
    air, _ = sim_raw("sortie", 400.0)
    for fmt in ("dataflash", "ulog"):
        ctrl = f"{fmt}/sortie/control/none"
        cases.append(Case(ctrl, fmt, "control", False, sim_writer(fmt, air), ctrl))
        for name in ("swap-gyro-xz", "gyro-z-inverted", "gyro-deg-s"):
            mut, fam, _ = SEMANTIC[name]
            cases.append(Case(f"{fmt}/sortie/{fam}/{name}", fmt, fam, True,
                              sim_writer(fmt, mut(air, np.random.default_rng(0))), ctrl))

    # ---- format-specific structure damage on the simulated base
    arrays, header = npz_arrays(raw, sim)
    for name, (arr, hdr, hb) in npz_structure(arrays, header).items():
        def build(d: Path, arr: Any = arr, hdr: Any = hdr, hb: Any = hb) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            return write_npz_arrays(arr, hdr, d / "case.npz", hb)
        cases.append(Case(f"npz/sim/structure/{name}", "npz", "structure", True, build,
                          "npz/sim/control/none"))

    def zip_bomb(d: Path) -> Path:  # a small file declaring 300 MB of zeros
        d.mkdir(parents=True, exist_ok=True)
        p = write_npz_arrays(arrays, header, d / "bomb.npz")
        with zipfile.ZipFile(p, "a", compression=zipfile.ZIP_DEFLATED) as zf, \
                zf.open("pad.npy", "w", force_zip64=True) as fh:
            hdr = io.BytesIO()
            np.lib.format.write_array_header_1_0(
                hdr, {"descr": "<f8", "fortran_order": False, "shape": (300 * 2**17,)})
            fh.write(hdr.getvalue())
            chunk = bytes(2**20)
            for _ in range(300):
                fh.write(chunk)
        return p
    cases.append(Case("npz/sim/structure/zip-bomb-300MB", "npz", "structure", True, zip_bomb,
                      "npz/sim/control/none"))

    for style in ("s", "ms", "us", "ns"):
        def build_t(d: Path, style: str = style) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            return write_merged_csv(raw, d / "sim.csv", time_style=style)
        # an epoch in s, ms, µs or ns is a valid encoding: read right, these are controls
        cases.append(Case(f"merged-csv/sim/structure/epoch-{style}", "merged-csv", "structure",
                          False, build_t, "merged-csv/sim/control/none"))
    for fname in ("Location", "Barometer", "GyroscopeUncalibrated", "AccelerometerUncalibrated",
                  "Metadata"):
        def build_f(d: Path, fname: str = fname) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            return write_sl_folder(raw, d / "sim", skip=(fname,))
        cases.append(Case(f"sl-folder/sim/structure/missing-{fname}", "sl-folder", "structure",
                          fname != "Metadata", build_f, "sl-folder/sim/control/none"))
    for omit in ("vehicle_air_data", "vehicle_gps_position", "sensor_combined"):
        def build_u(d: Path, omit: str = omit) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            return write_ulog(raw, d / "sim.ulg", omit=(omit,))
        cases.append(Case(f"ulog/sim/structure/missing-{omit}", "ulog", "structure",
                          omit != "vehicle_air_data", build_u, "ulog/sim/control/none"))
    for a, c in (("IMU", "BARO"), ("GPS", "IMU"), ("BARO", "GPS")):
        def build_d(d: Path, a: str = a, c: str = c) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            return write_dataflash(raw, d / "sim.bin", names={a: c, c: a})
        cases.append(Case(f"dataflash/sim/structure/fmt-swap-{a}-{c}", "dataflash",
                          "structure", True, build_d, "dataflash/sim/control/none"))
    r_shuf = raw.copy()
    r_shuf.extra["shuffle_records"] = True
    cases.append(Case("dataflash/sim/structure/records-unsorted", "dataflash", "structure",
                      False, sim_writer("dataflash", r_shuf), "dataflash/sim/control/none"))

    # ---- a 12-minute base for a 10-minute IMU gap while GNSS and baro go on (no rng draws:
    # the other cases keep their seeds)
    long_raw, long_sim = sim_raw(duration_s=720.0)
    gap = long_raw.copy()
    imu_gap(gap, 60.0, 660.0)
    alt_jump = SEMANTIC["gnss-alt-jump-1km-5s"][0](long_raw, np.random.default_rng(0))
    for fmt in ("npz", "sl-folder"):
        def build_l(d: Path, fmt: str = fmt, r: Raw = long_raw) -> Path:
            d.mkdir(parents=True, exist_ok=True)
            p = d / ("long" + SUFFIX[fmt])
            return write_npz(r, p, long_sim) if fmt == "npz" else WRITERS[fmt](r, p)
        ctrl = f"{fmt}/sim-long/control/none"
        cases.append(Case(ctrl, fmt, "control", False, build_l, ctrl))
        cases.append(Case(f"{fmt}/sim-long/semantic/imu-gap-10min", fmt, "semantic", True,
                          lambda d, fmt=fmt, b=build_l: b(d, fmt, gap), ctrl))
        cases.append(Case(f"{fmt}/sim-long/hostile/gnss-alt-jump-1km-5s", fmt, "hostile", True,
                          lambda d, fmt=fmt, b=build_l: b(d, fmt, alt_jump), ctrl))

    # ---- the small real cuts in tests/data (always present)
    real: list[tuple[str, str, Path]] = [
        ("merged-csv", "car-cut", TEST_DATA / "sensorlogger_car_1hz_cut.csv"),
        ("sl-folder", "ski-cut", TEST_DATA / "sensorlogger_ski_cut"),
    ]
    shared = shared_data_dir() if include_shared else None
    if shared is not None:
        real += [
            ("dataflash", "181", shared / "erle_pxf_181_gps_glitch" / "181.BIN"),
            ("dataflash", "218", shared / "erle_pxf_218" / "218.BIN"),
            ("dataflash", "loiter", shared / "erle_pxf_loiter_rtl" / "Loiter_RTL.bin"),
            ("ulog", "small", shared / "px4_ulog_samples" / "sample_log_small.ulg"),
            ("ulog", "events", shared / "px4_ulog_samples" / "sample_px4_events.ulg"),
            ("sl-folder", "ski", shared / "ski_iphone_100hz"),
            ("merged-csv", "car", shared / "car_phone_1hz_2025-07-18"
             / "2025-07-18_23-13-43.csv"),
        ]
    for fmt, base, src in real:
        if not src.exists():
            continue
        ctrl = f"{fmt}/{base}/control/none"
        cases.append(Case(ctrl, fmt, "control", False, _copy_src(src), ctrl))
        hl = HEADER_LEN.get(fmt, 0)
        muts = byte_mutations(hl)
        if base in ("218", "loiter", "ski", "car"):  # big logs: a third of the byte cases
            muts = {k: v for k, v in muts.items() if k in (
                "truncate-50pct", "flip-100", "swap-blocks", "header-noise", "zero-block")}
        for name, mut in muts.items():
            cases.append(_bytes_case(f"{fmt}/{base}/bytes/{name}", fmt, _copy_src(src), mut,
                                     int(rng.integers(2**31)), ctrl))
        if fmt == "merged-csv":
            text = src.read_text()
            for name, t in csv_text_mutations(text, np.random.default_rng(
                    int(rng.integers(2**31)))).items():
                def build_c(d: Path, t: str = t) -> Path:
                    d.mkdir(parents=True, exist_ok=True)
                    p = d / "case.csv"
                    p.write_text(t)
                    return p
                benign = name in ("crlf-line-ends", "bom")
                cases.append(Case(f"{fmt}/{base}/structure/{name}", fmt, "structure",
                                  not benign, build_c, ctrl))
        if fmt == "sl-folder" and base == "ski":
            # gyro x and z swapped in the phone's CSVs: the course-rate check refuses it (the
            # 12 s ski-cut has 14 fixes, too few for that check, and is not detected)
            def build_sw(d: Path, src: Path = src) -> Path:
                p = _copy_src(src)(d)
                for f in p.glob("Gyroscope*.csv"):
                    f.write_text(_swap_csv_columns(f.read_text(), "x", "z"))
                return p
            cases.append(Case(f"{fmt}/{base}/semantic/swap-gyro-xz", fmt, "semantic", True,
                              build_sw, ctrl))
        if fmt == "dataflash":
            patches = {
                "fmt-swap-IMU-BARO": lambda b: df_patch_fmt_names(b, "IMU", "BARO"),
                "accz-all-nan": lambda b: df_patch_field(b, "IMU", "AccZ", float("nan")),
                "press-all-zero": lambda b: df_patch_field(b, "BARO", "Press", 0.0),
                "gps-alt-zero": lambda b: df_patch_field(b, "GPS", "Alt", 0.0),
                "gyro-deg-s": lambda b: df_scale_fields(b, "IMU", ("GyrX", "GyrY", "GyrZ"),
                                                        180.0 / np.pi),
            }
            for name, fn in patches.items():
                cases.append(_bytes_case(f"{fmt}/{base}/structure/{name}", fmt, _copy_src(src),
                                         lambda b, g, fn=fn: fn(b), 0, ctrl))
    ids = [c.id for c in cases]
    assert len(ids) == len(set(ids)), "duplicate case ids"
    return cases


def replace_case(c: Case, **kw: Any) -> Case:
    return replace(c, **kw)
