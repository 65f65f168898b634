"""File I/O: drives (npz), real logs (``vnav_graph.io.readers``), results."""

from __future__ import annotations

from pathlib import Path

from ..types import Drive
from .drive_io import load_npz, save_npz


def load_drive(path: str | Path, check: bool = True) -> Drive:
    """Load a Drive from a ``.npz`` written by ``save_npz`` or from a real log (auto-detected
    by content through ``vnav_graph.io.readers``). Raises ValueError with a one-line reason.

    With ``check`` (default) the input sanity checks of :mod:`vnav_graph.io.sanity` run on the
    result (units, axes, time stamps, clipping, steps: repaired and reported in
    ``meta["warnings"]`` / ``meta["repaired"]``, or refused with ValueError). Messages the
    parsing libraries print or warn (pymavlink "bad header", numpy, pandas, dateutil) never
    reach the terminal: they are counted and summarised in one ``meta["warnings"]`` line.
    """
    from .quiet import quietly

    drive, noise = quietly(_load_unchecked, path)
    if noise.count:
        meta = dict(drive.meta)
        meta["warnings"] = [*list(meta.get("warnings") or []), noise.summary()]
        meta["library_messages"] = noise.count
        drive = drive.replace(meta=meta)
    if check:
        from .sanity import check_drive

        drive, noise = quietly(check_drive, drive)
        if noise.count:  # numpy warnings on odd values inside the checks
            meta = dict(drive.meta)
            meta["warnings"] = [*list(meta.get("warnings") or []), noise.summary()]
            drive = drive.replace(meta=meta)
    return drive


def _load_unchecked(path: str | Path) -> Drive:
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
    return read_log(p)


__all__ = ["load_drive", "load_npz", "save_npz"]
