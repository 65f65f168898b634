"""Trajectory exports of a finished ``run`` folder: CSV, KML, GPX and TUM.

``export_run(run_dir, formats, estimators)`` reads ``run_dir/summary.json``,
``run_dir/drive.json`` (origin, height datum, time reference and GNSS gaps of the drive,
written by ``run``), ``run_dir/estimates/<name>.parquet`` and, where the drive has a truth,
``run_dir/truth.parquet``, and writes ``run_dir/export/<name>.<ext>``: one file per estimator
and format, the truth as ``truth.<ext>``, plus ``all.kml`` with every track in one file.

Formats (``FORMATS``; docs/design.md lists them as output contracts):

- ``csv``: the Parquet's columns and units, one row per epoch, 12 significant digits; ``#``
  comment lines first give the units, frames, height datum, time reference, estimator,
  vnav_graph version and the drive (``pandas.read_csv(path, comment="#")`` reads it back).
- ``kml``: the track as a line (altitude mode absolute, the drive's heights; KML viewers take
  absolute altitudes as above mean sea level, so an ellipsoidal drive sits higher or lower by
  the geoid undulation: the description says which datum the heights are in), plus the
  withheld-GNSS windows of a real log's holdout scoring (or a simulated drive's GNSS outages)
  as separate placemarks. Each estimator has the colour the report draws it in
  (``report.palette``). Written with simplekml.
- ``gpx``: one track with elevation; UTC time where the drive has an absolute time
  (``drive.json`` ``t0_unix_s``), otherwise no ``<time>`` (the track's description says that the
  time is relative). Every point also carries the drive-clock time ``t_s`` in a
  ``vnav:t_s`` extension. Written with gpxpy.
- ``tum``: ``timestamp x y z qx qy qz qw`` (the format of the evo trajectory tools): drive-clock
  time [s], position in the local tangent-plane NED frame at the drive's origin [m] (x north,
  y east, z down), and the body-to-NED attitude quaternion (Hamilton, scalar last).

Vertical-only estimators (the loops, vkf4, vekf7, observer1d) have no horizontal track: they
export as CSV only, and ``export_run`` names what it skipped and why.
"""

from __future__ import annotations

from .formats import FORMATS, export_run, parse_formats
from .run_info import DRIVE_INFO, TRUTH_TABLE, drive_info, write_run_info

__all__ = ["DRIVE_INFO", "FORMATS", "TRUTH_TABLE", "drive_info", "export_run", "parse_formats",
           "write_run_info"]
