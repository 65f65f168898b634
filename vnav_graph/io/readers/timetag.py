"""RTKLIB time-tag files (``<stream>.tag``, written by str2str/rtknavi beside a logged stream).

Layout (little-endian): a 60-byte text header (``TIMETAG RTKLIB …``), ``uint32`` tick_f,
``uint32`` time (whole seconds since 1970-01-01 on the GPST scale, i.e. counting no leap
seconds), ``float64`` fraction of a second, then 8-byte blocks (``uint32`` milliseconds since
the start, ``uint32`` byte offset in the stream file).

``counter_to_gpst`` maps a device's millisecond counter onto GPST the way the logger's own
tools do: the first sample at the tag's start time, the last at start + the last block's
tick, linearly in between (the device clock's rate against GPST is the ratio of the two
spans and is reported).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .gpstime import GPS_EPOCH_UNIX_S

__all__ = ["TimeTag", "counter_to_gpst", "read_tag"]

HEADER_BYTES = 60
MAGIC = b"TIMETAG"


@dataclass(frozen=True)
class TimeTag:
    """start_gpst: GPST seconds since the GPS epoch of tick 0; ticks_ms, offsets: the blocks."""

    start_gpst: float
    ticks_ms: np.ndarray
    offsets: np.ndarray

    @property
    def span_s(self) -> float:
        return float(self.ticks_ms[-1]) / 1000.0 if self.ticks_ms.size else 0.0


def read_tag(path: str | Path) -> TimeTag:
    """Read a time-tag file; ValueError (one line) when it is not one or has no blocks."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ValueError(f"{p.name}: cannot read time-tag file ({exc.strerror})") from None
    if not raw.startswith(MAGIC) or len(raw) < HEADER_BYTES + 16:
        raise ValueError(f"{p.name}: not an RTKLIB time-tag file (no TIMETAG header)")
    _, sec, frac = struct.unpack_from("<IId", raw, HEADER_BYTES)
    body = raw[HEADER_BYTES + 16:]
    n = len(body) // 8
    if n == 0:
        raise ValueError(f"{p.name}: time-tag file has no time blocks")
    blocks = np.frombuffer(body[:n * 8], dtype="<u4").reshape(n, 2)
    return TimeTag(float(sec) + float(frac) - GPS_EPOCH_UNIX_S,
                   blocks[:, 0].astype(float), blocks[:, 1].astype(float))


def counter_to_gpst(counter_ms: np.ndarray, tag: TimeTag) -> tuple[np.ndarray, float]:
    """GPST seconds of each sample's millisecond counter (module docstring) and the device
    clock's rate (device seconds per GPST second)."""
    c = np.asarray(counter_ms, dtype=float)
    span_dev = (c[-1] - c[0]) / 1000.0
    if not span_dev > 0 or tag.span_s <= 0:
        raise ValueError("time-tag mapping: the counter or the tag file spans no time")
    rate = span_dev / tag.span_s
    return tag.start_gpst + (c - c[0]) / 1000.0 / rate, rate
