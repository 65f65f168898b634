"""Garbage stretches in a log file: zero bytes and unparsable data, with their size and place.

A log whose second half is zero bytes (a logger that pre-allocated its file, or a file system
that lost the last writes) reads as a shorter drive; the readers count one malformed record
at most. This scan finds, in the raw bytes of every file of the input,

- runs of NUL bytes;
- in a DataFlash log, stretches without a record header (``0xA3 0x95``): every record is at
  most 256 bytes long and starts with one, so a longer stretch holds no record;
- in a ULog, stretches where the chain of messages (size, known type) breaks, up to where a
  chain of ``ULOG_RESYNC`` well-formed messages starts again;
- in a CSV file, consecutive lines holding control bytes (other than tab / CR), which no
  CSV field carries: binary garbage written into a text file;

and reports each stretch of at least ``MIN_BYTES`` that covers at least ``MIN_FRACTION`` of
its file, as one ``meta["warnings"]`` line with its size, its share of the file and where
it starts (for a tail: how far into the drive the data were read).

Thresholds: the shared logs' longest legitimate NUL runs are 80 bytes (DataFlash) and 110
bytes (ULog), their longest header-free DataFlash stretch 89 bytes (an FMT record), and their
CSVs hold no control bytes: ``MIN_BYTES`` = 4 kB (a file-system block, the unit in which
writes are lost) is 37 times the longest. ``MIN_FRACTION`` = 2 %: smaller damage is left to
the readers' drop counts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

MIN_BYTES = 4096
MIN_FRACTION = 0.02
DF_HEADER = (0xA3, 0x95)
DF_MAX_RECORD = 256
ULOG_HEADER = 16  # bytes before the first message
ULOG_TYPES = frozenset(b"BFIMPQARDLCSO")  # the message types of ULog v1
ULOG_RESYNC = 8  # well-formed messages in a row that end a broken stretch
ULOG_MAX_OTHER = 1024  # bytes: the longest non-data message once data have begun


@dataclass(frozen=True)
class Stretch:
    """``length`` bytes of ``kind`` ("zero bytes" / "unparsable bytes") from byte ``start``
    of a file of ``size`` bytes."""

    file: str
    kind: str
    start: int
    length: int
    size: int

    @property
    def is_tail(self) -> bool:
        return self.start + self.length >= self.size

    def text(self, read_up_to_s: float | None) -> str:
        pct = 100.0 * self.length / self.size
        amount = f"{_kb(self.length)} ({pct:.0f} %)"
        if self.is_tail:
            where = f"the last {amount} of the file are {self.kind}"
            if read_up_to_s is not None:
                where += f": data read up to {read_up_to_s:.1f} s into the drive"
            return f"{self.file}: {where}"
        return (f"{self.file}: {amount} of {self.kind} from byte {self.start} "
                f"({100.0 * self.start / self.size:.0f} % into the file)")


def _kb(n: int) -> str:
    return f"{n / 1024:.0f} kB" if n >= 10 * 1024 else f"{n / 1024:.1f} kB"


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(start, length) of every run of True."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    s, e = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(s.tolist(), (e - s).tolist(), strict=True))


def _big(length: int, size: int) -> bool:
    return length >= MIN_BYTES and length >= MIN_FRACTION * size


def _zero_runs(b: NDArray[np.uint8], name: str) -> list[Stretch]:
    return [Stretch(name, "zero bytes", s, n, b.size) for s, n in _runs(b == 0)
            if _big(n, b.size)]


def _unparsable(b: NDArray[np.uint8], name: str, pieces: list[tuple[int, int]]
                ) -> list[Stretch]:
    """Stretches from (start, end) pieces: pieces closer than ``MIN_BYTES`` are joined (a
    stray header or text line inside garbage), mostly-zero ones are left to the zero scan."""
    joined: list[list[int]] = []
    for s, e in pieces:
        if e <= s:
            continue
        if joined and s - joined[-1][1] < MIN_BYTES:
            joined[-1][1] = e
        else:
            joined.append([s, e])
    return [Stretch(name, "unparsable bytes", s, e - s, b.size) for s, e in joined
            if _big(e - s, b.size) and np.count_nonzero(b[s:e]) > 0.5 * (e - s)]


def _dataflash_gaps(b: NDArray[np.uint8], name: str) -> list[Stretch]:
    """Header-free stretches that are not (mostly) zero bytes."""
    hits = np.flatnonzero((b[:-1] == DF_HEADER[0]) & (b[1:] == DF_HEADER[1]))
    starts = np.r_[0, hits + DF_MAX_RECORD]  # a record may run DF_MAX_RECORD past its header
    ends = np.r_[hits, b.size]
    keep = ends - starts >= DF_MAX_RECORD  # shorter: between two records, not garbage
    return _unparsable(b, name, list(zip(starts[keep].tolist(), ends[keep].tolist(),
                                         strict=True)))


def _ulog_chain(b: NDArray[np.uint8], pos: int, d_size: dict[int, int],
                limit: int | None = None) -> tuple[int, int]:
    """(where it breaks, messages) of the chain of well-formed ULog messages from ``pos``; at
    most ``limit`` messages. Well-formed: a known type, inside the file; a data message ('D')
    for a subscription id an 'A' message declared, as long as the first data message of that
    id (``d_size``: id → size, 0 until the first; filled as they come); once data messages
    have begun, any other message at most ``ULOG_MAX_OTHER`` bytes (logged text, parameter
    changes, subscriptions, sync and dropout markers are short)."""
    n = 0
    while pos + 3 <= b.size and (limit is None or n < limit):
        size = int(b[pos]) | (int(b[pos + 1]) << 8)
        typ = int(b[pos + 2])
        if typ not in ULOG_TYPES or pos + 3 + size > b.size:
            break
        if typ == ord("D"):
            msg_id = int(b[pos + 3]) | (int(b[pos + 4]) << 8) if size >= 2 else -1
            if msg_id not in d_size or d_size[msg_id] not in (0, size):
                break
            d_size[msg_id] = size
        elif typ == ord("A") and size >= 3:
            d_size.setdefault(int(b[pos + 4]) | (int(b[pos + 5]) << 8), 0)
        if typ != ord("D") and any(d_size.values()) and size > ULOG_MAX_OTHER:
            break
        pos += 3 + size
        n += 1
    return pos, n


def _ulog_gaps(b: NDArray[np.uint8], name: str) -> list[Stretch]:
    """Stretches where the ULog message chain is broken: from the break to the next place a
    chain of ``ULOG_RESYNC`` well-formed messages (or one ending the file) starts."""
    cand = np.flatnonzero(np.isin(b[2:], np.array(sorted(ULOG_TYPES), dtype=np.uint8)))
    d_size: dict[int, int] = {}
    pieces = []
    pos = ULOG_HEADER
    while True:
        pos, _ = _ulog_chain(b, pos, d_size)
        if pos + 3 > b.size:
            break
        nxt = b.size
        known = dict(d_size)  # a resync candidate must match the subscriptions seen so far
        for q in cand[np.searchsorted(cand, pos + 1):].tolist():
            end, n = _ulog_chain(b, q, dict(known), ULOG_RESYNC)
            if n >= ULOG_RESYNC or (n >= 3 and end == b.size):
                nxt = q
                break
        pieces.append((pos, nxt))
        pos = nxt
    return _unparsable(b, name, pieces)


def _csv_garbage(b: NDArray[np.uint8], name: str) -> list[Stretch]:
    """Runs of lines holding control bytes (NUL runs are reported as zero bytes)."""
    ctrl = ((b < 32) & (b != 9) & (b != 10) & (b != 13)) | (b == 127)
    if not ctrl.any():
        return []
    nl = np.flatnonzero(b == 10)
    line_start = np.r_[0, nl + 1]
    line_end = np.r_[nl + 1, b.size]
    keep = line_end > line_start
    line_start, line_end = line_start[keep], line_end[keep]
    csum = np.r_[0, np.cumsum(ctrl)]
    bad = (csum[line_end] - csum[line_start]) > 0
    return _unparsable(b, name, [(int(line_start[s]), int(line_end[s + n - 1]))
                                 for s, n in _runs(bad)])


def garbage_stretches(path: Path) -> list[Stretch]:
    """Every garbage stretch (module docstring) in the file at ``path``, or in the CSV files
    of a folder; ``[]`` for a ``.npz`` (a zip archive checks its own members)."""
    files = sorted(path.glob("*.csv")) if path.is_dir() else [path]
    out: list[Stretch] = []
    for f in files:
        try:
            b = np.fromfile(f, dtype=np.uint8)
        except OSError:
            continue
        if b.size < 2 or (b[0] == ord("P") and b[1] == ord("K")):
            continue
        name = f.name
        found = _zero_runs(b, name)
        if bytes(b[:3].tolist()) == bytes((DF_HEADER[0], DF_HEADER[1], 128)):
            found += _dataflash_gaps(b, name)
        elif bytes(b[:4].tolist()) == b"ULog":
            found += _ulog_gaps(b, name)
        elif f.suffix.lower() == ".csv":
            found += _csv_garbage(b, name)
        out += sorted(found, key=lambda s: s.start)
    return out
