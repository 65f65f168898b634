"""File I/O: drives (npz), real logs (``vnav_graph.io.readers``), results."""

from __future__ import annotations

from pathlib import Path

from ..types import Drive
from .drive_io import load_npz, save_npz


def load_drive(path: str | Path, check: bool = True, column_map: str | Path | None = None,
               height_datum: str | None = None) -> Drive:
    """Load a Drive from a ``.npz`` written by ``save_npz`` or from a real log (auto-detected
    by content through ``vnav_graph.io.readers``). Raises ValueError with a one-line reason.

    With ``check`` (default) the input sanity checks of :mod:`vnav_graph.io.sanity` run on the
    result (units, axes, time stamps, clipping, steps: repaired and reported in
    ``meta["warnings"]`` / ``meta["repaired"]``, or refused with ValueError). Messages the
    parsing libraries print or warn (pymavlink "bad header", numpy, pandas, dateutil) never
    reach the terminal: they are counted and summarised in one ``meta["warnings"]`` line.
    """
    from .quiet import quietly

    drive, noise = quietly(_load_unchecked, path, column_map, height_datum)
    if noise.count:
        meta = dict(drive.meta)
        meta["warnings"] = [*list(meta.get("warnings") or []), noise.summary()]
        meta["library_messages"] = noise.count
        drive = drive.replace(meta=meta)
    drive = _with_garbage_stretches(drive, Path(path))
    if check:
        from .sanity import check_drive

        drive, noise = quietly(check_drive, drive)
        if noise.count:  # numpy warnings on odd values inside the checks
            meta = dict(drive.meta)
            meta["warnings"] = [*list(meta.get("warnings") or []), noise.summary()]
            drive = drive.replace(meta=meta)
    return drive


def _with_garbage_stretches(drive: Drive, path: Path) -> Drive:
    """``meta["warnings"]`` (and ``meta["garbage"]``) for the zero-byte and unparsable
    stretches of the input's files (:mod:`vnav_graph.io.tails`)."""
    from .tails import garbage_stretches

    found = garbage_stretches(path)
    if not found:
        return drive
    end_s = None
    if path.is_file():
        streams = [s for s in (drive.imu, drive.gnss, drive.baro, drive.mag)
                   if s is not None and len(s)]
        end_s = max(float(s.t[-1]) for s in streams) - min(float(s.t[0]) for s in streams)
    meta = dict(drive.meta)
    meta["warnings"] = [*list(meta.get("warnings") or []), *(s.text(end_s) for s in found)]
    meta["garbage"] = [{"file": s.file, "kind": s.kind, "start_byte": s.start,
                        "bytes": s.length, "file_bytes": s.size} for s in found]
    return drive.replace(meta=meta)


def _load_unchecked(path: str | Path, column_map: str | Path | None = None,
                    height_datum: str | None = None) -> Drive:
    p = Path(path)
    if not p.exists():
        raise ValueError(f"no such file or directory: {p}")
    if p.is_file():
        with open(p, "rb") as fh:
            head = fh.read(4)
        if head[:2] == b"PK":  # numpy .npz is a zip archive
            return load_npz(p)
    try:
        from .readers import read_log
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.endswith("readers"):
            raise ValueError(f"{p.name}: not a vnav_graph drive (.npz) and no log readers in "
                             "this build") from None
        raise
    return read_log(p, column_map, height_datum)


__all__ = ["load_drive", "load_npz", "save_npz"]
