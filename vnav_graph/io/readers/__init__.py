"""Real-log readers → :class:`~vnav_graph.types.Drive`, auto-detected by content.

``read_log(path)`` looks at the bytes, not at the file name:

- ``0xA3 0x95 0x80`` (DataFlash FMT record) → :func:`.ardupilot.read_dataflash`,
  ``format = "ardupilot-dataflash"``;
- ``ULog\\x01\\x12\\x35`` magic → :func:`.px4.read_ulog`, ``"px4-ulog"``;
- a folder of CSVs whose header starts ``time,seconds_elapsed`` →
  :func:`.sensorlogger.read_sensorlogger_folder`, ``"sensorlogger-folder"``;
- a CSV whose header has ``time``, ``latitude``, ``longitude`` and ``acc_*`` or ``pressure``
  columns → :func:`.sensorlogger.read_merged_csv`, ``"sensorlogger-merged-1hz"``;
- a folder with a column map (a ``*.toml`` with an ``[imu]`` table), or any folder with
  ``column_map=`` given → :func:`.column_map.read_mapped`, ``"column-map"`` (plain IMU text,
  RTKLIB ``.pos`` or NMEA GNSS).

Every reader cleans and reports: ``Drive.meta`` has ``source="log"``, ``name``, ``format``,
``dropped`` / ``repaired`` (per stream: reason → count), ``gaps`` (logging gaps as
``[start_s, length_s]``), ``notes``, and ``onboard`` (the autopilot's own altitude) where
the log has one. Anything that cannot be read raises ``ValueError`` with a one-line reason.
"""

from __future__ import annotations

from pathlib import Path

from ...types import Drive

__all__ = ["detect_format", "read_log"]


def detect_format(path: str | Path) -> str:
    """Name of the log format of ``path`` from its content (ValueError when unknown)."""
    from .ardupilot import is_dataflash
    from .px4 import is_ulog
    from .sensorlogger import is_merged_csv, is_sensorlogger_folder

    p = Path(path)
    if not p.exists():
        raise ValueError(f"no such file or directory: {p}")
    if p.is_dir():
        from .column_map import find_map

        if find_map(p) is not None:
            return "column-map"
        if is_sensorlogger_folder(p):
            return "sensorlogger-folder"
        raise ValueError(f"{p.name}: folder is not a Sensor Logger export "
                         "(no CSV with time,seconds_elapsed columns) and has no column map "
                         "(a *.toml with an [imu] table, or --map MAP.toml)")
    with open(p, "rb") as fh:
        head = fh.read(4096)
    if not head:
        raise ValueError(f"{p.name}: file is empty")
    if is_dataflash(head):
        return "ardupilot-dataflash"
    if is_ulog(head):
        return "px4-ulog"
    if is_merged_csv(head):
        return "sensorlogger-merged-1hz"
    from .rtklib_pos import is_pos

    if is_pos(head):
        raise ValueError(f"{p.name}: an RTKLIB solution holds GNSS only: run the folder with "
                         "its IMU file and a column map (--map MAP.toml, docs/column_maps.md)")
    raise ValueError(f"{p.name}: unknown log format (not ArduPilot DataFlash, PX4 ULog or a "
                     "Sensor Logger CSV export; for plain IMU/GNSS files run their folder "
                     "with a column map, --map MAP.toml)")


def read_log(path: str | Path, column_map: str | Path | None = None,
             height_datum: str | None = None) -> Drive:
    """Read a real log (format detected from content) into a Drive; ValueError if unreadable.
    ``column_map``: a TOML column map for a folder of plain files (``height_datum``: the GNSS
    file's datum where its header and the map are silent)."""
    if column_map is not None:
        from .column_map import read_mapped

        if not Path(path).is_dir():
            raise ValueError(f"--map needs a folder, not the file {Path(path).name}")
        return read_mapped(path, column_map, height_datum)
    fmt = detect_format(path)
    if fmt == "column-map":
        from .column_map import read_mapped

        return read_mapped(path, None, height_datum)
    if fmt == "ardupilot-dataflash":
        from .ardupilot import read_dataflash

        return read_dataflash(path)
    if fmt == "px4-ulog":
        from .px4 import read_ulog

        return read_ulog(path)
    from . import sensorlogger

    if fmt == "sensorlogger-folder":
        return sensorlogger.read_sensorlogger_folder(path)
    return sensorlogger.read_merged_csv(path)
