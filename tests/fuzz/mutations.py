"""The damage the corrupted-input corpus (``corpus``) applies: mutations of the streams
before they are written (``SEMANTIC``: units, axes, NaN, hostile physics), of the written bytes
(``byte_mutations``), of a ``.npz``'s arrays and header (``npz_structure``), of a merged CSV's
text (``csv_text_mutations``) and of a DataFlash log's records (``df_patch_fmt_names``,
``df_patch_field``). Each is deterministic given its random generator."""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from typing import Any

import numpy as np

from .writers import G0, Raw, dataflash_records, dataflash_scale_field


# --------------------------------------------------------------- semantic / hostile
def _m(fn: Callable[[Raw, np.random.Generator], None]) -> Callable[[Raw, np.random.Generator],
                                                                    Raw]:
    def wrap(raw: Raw, rng: np.random.Generator) -> Raw:
        r = raw.copy()
        fn(r, rng)
        return r
    return wrap


def _clip(r: Raw, col: str, axis: int, limit: float, t0: float, dur: float) -> None:
    """Drive the axis hard past ``limit`` for ``dur`` seconds, then pin it at ±limit
    (what a saturated sensor logs)."""
    x = getattr(r, col)
    m = (r.t_imu >= r.t_imu[0] + t0) & (r.t_imu < r.t_imu[0] + t0 + dur)
    ph = np.linspace(0, 6 * np.pi, int(m.sum()))
    x[m, axis] = np.clip(x[m, axis] + 3 * limit * np.sin(ph), -limit, limit)


def _baro_step(r: Raw, dz: float, t0: float, t1: float | None) -> None:
    from vnav_graph.geo.atmosphere import isa_pressure

    m = r.t_baro >= r.t_baro[0] + t0
    if t1 is not None:
        m &= r.t_baro < r.t_baro[0] + t1
    r.baro_alt[m] += dz
    r.press = np.asarray(isa_pressure(r.baro_alt), dtype=float)


def _gnss_jump(r: Raw, k: int, dn_m: float, dh_m: float) -> None:
    r.lat_deg[k] += dn_m / 111_320.0
    r.h[k] += dh_m


def _gnss_held_jump(r: Raw, t0: float, dur: float, dn_m: float) -> None:
    """Every fix in [t0, t0 + dur) s moved ``dn_m`` north (a receiver glitch held a while)."""
    m = (r.t_gnss >= r.t_gnss[0] + t0) & (r.t_gnss < r.t_gnss[0] + t0 + dur)
    r.lat_deg[m] += dn_m / 111_320.0


def _gnss_held_height_jump(r: Raw, t0: float, dur: float, dh_m: float) -> None:
    """Every fix in [t0, t0 + dur) s raised by ``dh_m`` (a height glitch held a while)."""
    m = (r.t_gnss >= r.t_gnss[0] + t0) & (r.t_gnss < r.t_gnss[0] + t0 + dur)
    r.h[m] += dh_m


def imu_gap(r: Raw, t0: float, t1: float) -> None:
    keep = ~((r.t_imu > r.t_imu[0] + t0) & (r.t_imu < r.t_imu[0] + t1))
    r.t_imu, r.gyro, r.acc = r.t_imu[keep], r.gyro[keep], r.acc[keep]


def _zero_second_half(r: Raw) -> None:
    """Every value of every record in the second half of the drive zeroed, stamps kept (a
    logger that went on writing records of zeros)."""
    mid = 0.5 * (r.t_imu[0] + r.t_imu[-1])
    m = r.t_imu > mid
    r.gyro[m], r.acc[m] = 0.0, 0.0
    m = r.t_gnss > mid
    r.lat_deg[m], r.lon_deg[m], r.h[m], r.vel_n[m] = 0.0, 0.0, 0.0, 0.0
    m = r.t_baro > mid
    r.press[m], r.baro_alt[m] = 0.0, 0.0


def _shuffle_imu_t(r: Raw, rng: np.random.Generator) -> None:
    r.t_imu = rng.permutation(r.t_imu)
    r.extra["shuffle_records"] = True  # written in this order, not sorted by stamp


def _nan_rows(r: Raw, rng: np.random.Generator, frac: float) -> None:
    k = rng.choice(r.t_imu.size, int(frac * r.t_imu.size), replace=False)
    r.acc[k, rng.integers(0, 3)] = np.nan


def _constant_gnss(r: Raw) -> None:
    r.lat_deg[:] = r.lat_deg[0]
    r.lon_deg[:] = r.lon_deg[0]
    r.h[:] = r.h[0]
    r.vel_n[:] = 0.0


# name → (mutation, family, formats it applies to (None: all))
SEMANTIC: dict[str, tuple[Callable[[Raw, np.random.Generator], Raw], str, tuple[str, ...] |
                          None]] = {
    "accel-in-g": (_m(lambda r, g: setattr(r, "acc", r.acc / G0)), "semantic", None),
    "accel-times-g": (_m(lambda r, g: setattr(r, "acc", r.acc * G0)), "semantic", None),
    "gyro-deg-s": (_m(lambda r, g: setattr(r, "gyro", np.degrees(r.gyro))), "semantic", None),
    "swap-acc-xz": (_m(lambda r, g: setattr(r, "acc", r.acc[:, [2, 1, 0]])), "semantic", None),
    "swap-gyro-xz": (_m(lambda r, g: setattr(r, "gyro", r.gyro[:, [2, 1, 0]])), "semantic",
                     None),
    "gyro-z-inverted": (_m(lambda r, g: setattr(r, "gyro", r.gyro * np.array([1.0, 1.0, -1.0]))),
                        "semantic", None),
    "acc-sign-flipped": (_m(lambda r, g: setattr(r, "acc", -r.acc)), "semantic",
                         ("npz", "dataflash", "ulog")),
    "accz-all-nan": (_m(lambda r, g: r.acc.__setitem__((slice(None), 2), np.nan)), "semantic",
                     None),
    "acc-nan-10pct": (_m(lambda r, g: _nan_rows(r, g, 0.10)), "semantic", None),
    "acc-nan-95pct": (_m(lambda r, g: _nan_rows(r, g, 0.95)), "semantic", None),
    "gyro-inf": (_m(lambda r, g: r.gyro.__setitem__((slice(100, 110), 0), np.inf)),
                 "semantic", None),
    "imu-time-ms": (_m(lambda r, g: setattr(r, "t_imu", r.t_imu * 1e3)), "semantic",
                    ("npz", "ulog", "sl-folder")),
    "imu-time-us-as-s": (_m(lambda r, g: setattr(r, "t_imu", r.t_imu * 1e-3)), "semantic",
                         ("npz", "dataflash", "ulog", "sl-folder")),
    "imu-time-shuffled": (_m(_shuffle_imu_t), "semantic", ("npz", "ulog", "sl-folder")),
    "values-zeroed-second-half": (_m(lambda r, g: _zero_second_half(r)), "semantic", None),
    "imu-gap-70s": (_m(lambda r, g: imu_gap(r, 20.0, 90.0)), "semantic", None),
    "baro-alt-feet": (_m(lambda r, g: setattr(r, "baro_alt", r.baro_alt / 0.3048)),
                      "semantic", ("npz",)),
    "baro-alt-negated": (_m(lambda r, g: setattr(r, "baro_alt", -r.baro_alt + 2 * r.h[0])),
                         "semantic", ("npz",)),
    "pressure-hpa": (_m(lambda r, g: setattr(r, "press", r.press / 100.0)), "semantic",
                     ("dataflash", "ulog")),
    "pressure-constant": (_m(lambda r, g: (r.press.__setitem__(slice(None), r.press[0]),
                                           r.baro_alt.__setitem__(slice(None), r.baro_alt[0]))),
                          "semantic", None),
    "gnss-alt-feet": (_m(lambda r, g: setattr(r, "h", r.h / 0.3048)), "semantic", None),
    "gnss-alt-zero": (_m(lambda r, g: r.h.__setitem__(slice(None), 0.0)), "semantic", None),
    "gnss-constant": (_m(lambda r, g: _constant_gnss(r)), "semantic", None),
    "clip-accel-16g": (_m(lambda r, g: _clip(r, "acc", 2, 16 * G0, 40.0, 2.0)), "hostile",
                       None),
    "clip-accel-4g-x": (_m(lambda r, g: _clip(r, "acc", 0, 4 * G0, 60.0, 1.0)), "hostile",
                        None),
    "clip-gyro-250dps": (_m(lambda r, g: _clip(r, "gyro", 2, np.radians(250), 50.0, 1.5)),
                         "hostile", None),
    "baro-step-100m": (_m(lambda r, g: _baro_step(r, 100.0, 60.0, None)), "hostile", None),
    "baro-spike-300m": (_m(lambda r, g: _baro_step(r, 300.0, 70.0, 70.5)), "hostile", None),
    "gnss-jump-500m": (_m(lambda r, g: _gnss_jump(r, 500, 500.0, 300.0)), "hostile", None),
    "gnss-far-fix": (_m(lambda r, g: _gnss_jump(r, 700, 8.5e6, 0.0)), "hostile", None),
    "gnss-jump-10km-5s": (_m(lambda r, g: _gnss_held_jump(r, 60.0, 5.0, 1.0e4)), "hostile",
                          None),
    "gnss-alt-jump-1km-5s": (_m(lambda r, g: _gnss_held_height_jump(r, 60.0, 5.0, 1.0e3)),
                             "hostile", None),
}


# ---------------------------------------------------------------------- byte mutations
def _flip(b: bytearray, rng: np.random.Generator, n: int, lo: int) -> None:
    for p in rng.integers(lo, len(b), n):
        b[int(p)] ^= 1 << int(rng.integers(0, 8))


def byte_mutations(header_len: int) -> dict[str, Callable[[bytes, np.random.Generator], bytes]]:
    """Byte-level damage; ``header_len`` bytes at the start count as the file header."""
    def trunc(f: float) -> Callable[[bytes, np.random.Generator], bytes]:
        return lambda b, g: b[:max(1, int(len(b) * f))]

    def flips(n: int) -> Callable[[bytes, np.random.Generator], bytes]:
        def fn(b: bytes, g: np.random.Generator) -> bytes:
            x = bytearray(b)
            _flip(x, g, n, min(header_len, len(x) - 1))
            return bytes(x)
        return fn

    def swap(b: bytes, g: np.random.Generator) -> bytes:
        n = max(64, len(b) // 20)
        i, j = sorted(int(v) for v in g.integers(header_len, max(header_len + 1, len(b) - n), 2))
        if j - i < n:
            return b
        return b[:i] + b[j:j + n] + b[i + n:j] + b[i:i + n] + b[j + n:]

    def dup(b: bytes, g: np.random.Generator) -> bytes:
        n = max(64, len(b) // 30)
        i = int(g.integers(header_len, max(header_len + 1, len(b) - n)))
        return b[:i + n] + b[i:i + n] + b[i + n:]

    def zero(b: bytes, g: np.random.Generator) -> bytes:
        n = max(64, len(b) // 25)
        i = int(g.integers(header_len, max(header_len + 1, len(b) - n)))
        return b[:i] + bytes(n) + b[i + n:]

    def zero_half(b: bytes, g: np.random.Generator) -> bytes:
        n = len(b) // 2
        return b[:n] + bytes(len(b) - n)

    def noise_half(b: bytes, g: np.random.Generator) -> bytes:
        n = len(b) // 2
        return b[:n] + g.integers(0, 256, len(b) - n, dtype=np.uint8).tobytes()

    def head_zero(b: bytes, g: np.random.Generator) -> bytes:
        n = max(8, header_len)
        return bytes(n) + b[n:]

    def head_noise(b: bytes, g: np.random.Generator) -> bytes:
        n = max(8, header_len)
        return g.integers(0, 256, n, dtype=np.uint8).tobytes() + b[n:]

    def head_flip(b: bytes, g: np.random.Generator) -> bytes:
        x = bytearray(b)
        for p in g.integers(0, max(8, header_len), 3):
            x[int(p)] ^= 0xFF
        return bytes(x)

    return {
        "truncate-2pct": trunc(0.02), "truncate-30pct": trunc(0.30),
        "truncate-50pct": trunc(0.50), "truncate-77pct": trunc(0.77),
        "truncate-last-byte": lambda b, g: b[:-1],
        "flip-1": flips(1), "flip-10": flips(10), "flip-100": flips(100),
        "flip-1000": flips(1000),
        "swap-blocks": swap, "dup-block": dup, "zero-block": zero,
        "zeroed-second-half": zero_half, "noise-second-half": noise_half,
        "header-zeroed": head_zero, "header-noise": head_noise, "header-flip": head_flip,
    }


HEADER_LEN = {"npz": 64, "dataflash": 89 * 4, "ulog": 16, "csv": 0}


# --------------------------------------------------------------- format-specific damage
def npz_structure(arrays: dict[str, np.ndarray], header: dict[str, Any]
                  ) -> dict[str, tuple[dict[str, np.ndarray], Any, bytes | None]]:
    """name → (arrays, header, raw header bytes or None) for .npz damage."""
    def without(*keys: str) -> dict[str, np.ndarray]:
        return {k: v for k, v in arrays.items() if k not in keys}

    def with_(**kw: Any) -> dict[str, np.ndarray]:
        return {**arrays, **kw}

    def hdr(**kw: Any) -> dict[str, Any]:
        h = json.loads(json.dumps(header))
        for k, v in kw.items():
            if v is _DEL:
                h.pop(k, None)
            else:
                h[k] = v
        return h

    spec_bad = json.loads(json.dumps(header))
    spec_str = None
    if isinstance(spec_bad.get("imu_spec"), dict):
        spec_bad["imu_spec"]["fields"]["gyro_noise_density"] = "lots"
        spec_str = spec_bad
    truth_keys = [k for k in arrays if k.startswith("truth_")]
    t = arrays["imu_t"]
    q_nan = arrays.get("truth_q_nb")
    cases: dict[str, tuple[dict[str, np.ndarray], Any, bytes | None]] = {
        "missing-imu_t": (without("imu_t"), header, None),
        "missing-imu_accel_b": (without("imu_accel_b"), header, None),
        "missing-gnss_lla": (without("gnss_lla"), header, None),
        "missing-baro": (without("baro_t", "baro_alt"), header, None),
        "missing-gnss": (without("gnss_t", "gnss_lla", "gnss_pos_sd", "gnss_vel_n",
                                 "gnss_vel_sd", "gnss_lever_arm_b"), header, None),
        "missing-header": (arrays, header, b""),
        "header-not-json": (arrays, header, b"{not json"),
        "header-list": (arrays, header, b"[1, 2, 3]"),
        "header-no-format": (arrays, hdr(format=_DEL), None),
        "header-meta-list": (arrays, hdr(meta=[1, 2]), None),
        "header-meta-null": (arrays, hdr(meta=None), None),
        "header-spec-list": (arrays, hdr(imu_spec=[1, 2]), None),
        "header-spec-string": (arrays, hdr(baro_spec="BaroSpec"), None),
        "header-spec-unknown-type": (arrays, hdr(gnss_spec={"type": "Foo", "fields": {}}),
                                     None),
        "header-baro-truth-missing-key": (arrays, hdr(baro_truth={"scale": 0.01}), None),
        "header-baro-truth-string": (arrays, hdr(baro_truth={"scale": "x",
                                                             "latency_s": 0.1}), None),
        "imu_t-int64-ms": (with_(imu_t=np.round(t * 1e3).astype(np.int64)), header, None),
        "imu_t-float-ms": (with_(imu_t=np.round(t * 1e3)), header, None),
        "baro_alt-bool": (with_(baro_alt=arrays["baro_alt"] > np.median(arrays["baro_alt"])),
                          header, None),
        "imu_accel-float32": (with_(imu_accel_b=arrays["imu_accel_b"].astype(np.float32)),
                              header, None),
        "imu_accel-strings": (with_(imu_accel_b=arrays["imu_accel_b"].astype(str)), header,
                              None),
        "gnss_lla-2d-wrong-shape": (with_(gnss_lla=arrays["gnss_lla"][:, :2]), header, None),
        "imu_t-scalar": (with_(imu_t=np.array(1.0)), header, None),
        "imu-lengths-differ": (with_(imu_gyro_b=arrays["imu_gyro_b"][:-5]), header, None),
    }
    if spec_str is not None:
        cases["header-spec-field-string"] = (arrays, spec_str, None)
    if truth_keys:
        cases["truth-all-removed"] = (without(*truth_keys), header, None)
        cases["truth-lla-removed"] = (without("truth_lla"), header, None)
        tl = arrays["truth_lla"].copy()
        tl[10:20, 2] = np.nan
        cases["truth-height-nan"] = (with_(truth_lla=tl), header, None)
        if q_nan is not None:
            q = q_nan.copy()
            q[:] = np.nan
            cases["truth-quat-nan"] = (with_(truth_q_nb=q), header, None)
    return cases


class _Del:
    pass


_DEL = _Del()


def csv_text_mutations(text: str, rng: np.random.Generator) -> dict[str, str]:
    """Merged-CSV damage on the text: fields, columns, encodings."""
    lines = text.splitlines()
    head, body = lines[0], lines[1:]
    cols = head.split(",")

    def drop_col(name: str) -> str:
        j = cols.index(name)
        return "\n".join(",".join(c for i, c in enumerate(ln.split(",")) if i != j)
                         for ln in lines) + "\n"

    def rename_col(name: str, new: str) -> str:
        return "\n".join([head.replace(name, new, 1)] + body) + "\n"

    def missing_comma(k: int) -> str:
        out = list(lines)
        for i in rng.choice(np.arange(1, len(lines)), k, replace=False):
            parts = out[int(i)].split(",")
            j = int(rng.integers(1, len(parts) - 1))
            parts[j] = parts[j] + parts.pop(j + 1)  # two fields glued: one field short
            out[int(i)] = ",".join(parts)
        return "\n".join(out) + "\n"

    def extra_field(k: int) -> str:
        out = list(lines)
        for i in rng.choice(np.arange(1, len(lines)), k, replace=False):
            out[int(i)] = out[int(i)] + ",1.0"
        return "\n".join(out) + "\n"

    def garbage_values(k: int) -> str:
        out = list(lines)
        for i in rng.choice(np.arange(1, len(lines)), k, replace=False):
            parts = out[int(i)].split(",")
            parts[int(rng.integers(1, len(parts)))] = "n/a"
            out[int(i)] = ",".join(parts)
        return "\n".join(out) + "\n"

    muts = {
        "missing-comma-1-row": missing_comma(1),
        "missing-comma-10-rows": missing_comma(10),
        "extra-field-5-rows": extra_field(5),
        "garbage-values-20-rows": garbage_values(20),
        "header-only": head + "\n",
        "empty": "",
        "crlf-line-ends": "\r\n".join(lines) + "\r\n",
        "bom": "\ufeff" + text,
        "semicolons": text.replace(",", ";"),
        "header-repeated-mid": "\n".join(lines[:len(lines) // 2] + [head]
                                         + lines[len(lines) // 2:]) + "\n",
        "rows-reversed": "\n".join([head] + body[::-1]) + "\n",
        "rows-shuffled": "\n".join([head] + [body[int(i)] for i in
                                             rng.permutation(len(body))]) + "\n",
    }
    for c in ("acc_z", "gyro_x", "pressure", "latitude", "altitude", "time"):
        if c in cols:
            muts[f"missing-column-{c}"] = drop_col(c)
    if "acc_x" in cols and "acc_z" in cols:
        h2 = head.replace("acc_x", "TMPX").replace("acc_z", "acc_x").replace("TMPX", "acc_z")
        muts["acc-xz-header-swapped"] = "\n".join([h2] + body) + "\n"
    if "pressure" in cols:
        muts["pressure-renamed"] = rename_col("pressure", "press")
    return muts


def df_patch_fmt_names(b: bytes, a: str, c: str) -> bytes:
    """Swap the names of messages ``a`` and ``c`` in a DataFlash log's FMT records."""
    out = bytearray(b)
    i = 0
    while True:
        i = out.find(b"\xa3\x95\x80", i)
        if i < 0 or i + 89 > len(out):
            break
        name = bytes(out[i + 5:i + 9]).rstrip(b"\x00").decode("ascii", "replace")
        if name == a:
            out[i + 5:i + 9] = c.encode().ljust(4, b"\x00")
        elif name == c:
            out[i + 5:i + 9] = a.encode().ljust(4, b"\x00")
        i += 89
    return bytes(out)


def df_patch_field(b: bytes, msg: str, col: str, value: float) -> bytes:
    """Set one float field of every ``msg`` record (records walked by
    ``writers.dataflash_records``)."""
    out = bytearray(b)
    n = len(out)
    for i, name, fmt, cols, ln in dataflash_records(out):
        if name == msg and col in cols and i + ln <= n:
            off = i + 3
            for c, ch in zip(cols, fmt, strict=False):
                size = struct.calcsize("<" + _PYMAV.get(ch, "B"))
                if c == col and ch == "f":
                    out[off:off + 4] = struct.pack("<f", value)
                elif c == col and ch in "eiL" and np.isfinite(value):
                    scale = {"e": 100.0, "i": 1.0, "L": 1e7}[ch]
                    out[off:off + 4] = struct.pack("<i", int(value * scale))
                off += size
    return bytes(out)


_PYMAV = {"a": "64s", "b": "b", "B": "B", "g": "e", "h": "h", "H": "H", "i": "i", "I": "I",
          "f": "f", "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I",
          "L": "i", "d": "d", "M": "b", "q": "q", "Q": "Q"}


def df_scale_fields(b: bytes, msg: str, cols: tuple[str, ...], factor: float) -> bytes:
    """Every ``msg`` record's fields ``cols`` multiplied by ``factor`` (e.g. a gyro logged in
    deg/s: ``IMU`` ``GyrX/Y/Z`` × 180/π)."""
    for c in cols:
        b = dataflash_scale_field(b, msg, c, factor)
    return b
