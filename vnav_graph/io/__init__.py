"""File I/O: drives (npz), real logs (``vnav_graph.io.readers``), results."""

from __future__ import annotations

from pathlib import Path

from ..types import Drive
from .drive_io import load_npz, save_npz


def load_drive(path: str | Path) -> Drive:
    """Load a Drive from a ``.npz`` written by ``save_npz`` or from a real log (auto-detected
    by content through ``vnav_graph.io.readers``). Raises ValueError with a one-line reason."""
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
