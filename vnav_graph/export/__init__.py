"""Trajectory exports of a finished ``run`` folder: CSV, KML, GPX and TUM.

``export_run(run_dir, formats, estimators, online, full_rate)`` reads ``run_dir/summary.json``,
``run_dir/drive.json`` (origin, height datum, time reference and GNSS gaps of the drive,
written by ``run``), ``run_dir/estimates/<name>.parquet`` and, where the drive has a truth,
``run_dir/truth.parquet``, and writes ``run_dir/export/<name>.<ext>``: one file per estimator
and format, the truth as ``truth.<ext>``, plus ``all.kml`` with every track in one file.

Final and online answers: ``estimates/<name>.parquet`` is the estimator's final answer (a
smoother's smoothed trajectory, a filter's forward pass); a causal estimator (the filters,
graph-isam2) also has ``estimates/<name>.online.parquet``, its online (real-time) answer,
each epoch's state right after its own update. ``online=True`` (``export --online``) writes
those as ``<name>.online.<ext>`` (and ``all.online.kml``). Every file says which answer it
holds: the CSV's side file, the KML and GPX descriptions and the TUM ``#`` lines.

Rows: the epochs on the 20 Hz grid of the drive clock (``tables.EXPORT_RATE_HZ``, the graph
smoothers' output rate: t a multiple of 0.05 s), taken, never interpolated, so every track
pairs row by row with the truth by time stamp (the 50 Hz ekf keeps every 0.1 s; a track off
the grid, on a log's own clock, is thinned to rows at least 0.0475 s apart:
``tables.at_rate``).
``full_rate=True`` (``--full-rate``) writes every epoch (the truth and the vertical filters
are at the IMU rate).

Formats (``FORMATS``; docs/design.md lists them as output contracts):

- ``csv``: the Parquet's columns, one header row and one row per epoch, 12 significant
  digits, empty where not estimated. Angles in degrees (``lat_deg``, ``lon_deg``,
  ``roll_deg``..., ``att_*_sd_deg``, ``bias_gyro_*_degps``), every other column in the SI
  unit that ends its name (``alt_m``, ``vel_n_mps``). The side file
  ``<name>.csv-metadata.json`` (W3C CSV on the Web) says which answer it is, the drive, the
  height datum, the time reference, the tangent-plane origin, the rows' rate and each
  column's unit and meaning (``tables.csv_metadata``).
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
  y east, z down), and the body-to-NED attitude quaternion (Hamilton, scalar last), after
  ``#`` lines naming the answer, the drive and the frame (evo's reader skips them).

Vertical-only estimators (the loops, vkf4, vekf7, observer1d) have no horizontal track: they
export as CSV only, and ``export_run`` names what it skipped and why
(``ExportResult.skipped_line``: one line for all of them).
"""

from __future__ import annotations

from .formats import FORMATS, ExportResult, export_run, parse_formats
from .run_info import DRIVE_INFO, TRUTH_TABLE, drive_info, write_run_info
from .tables import EXPORT_RATE_HZ

__all__ = ["DRIVE_INFO", "EXPORT_RATE_HZ", "FORMATS", "TRUTH_TABLE", "ExportResult",
           "drive_info", "export_run", "parse_formats", "write_run_info"]
