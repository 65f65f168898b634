"""The rows and columns of an export: the output rate, the CSV's degrees and its side file.

- ``at_rate(table, rate_hz)``: the rows of a trajectory table on the ``1 / rate_hz`` grid of
  the drive clock, taken, never interpolated. A track keeps its epochs that lie on the grid
  (t a multiple of 0.05 s at 20 Hz), so every exported track pairs row by row, by time stamp,
  with the truth and with the others: the 200 Hz truth and the 20 Hz graph smoothers keep
  every 0.05 s, the 50 Hz ekf every 0.1 s (the ekf has no epoch at 0.05 s). Pairing rows
  0.01 s apart would add 0.2 m of apparent error at 20 m/s, so the grid is not filled with
  near epochs. A track whose epochs seldom lie on the grid (in under a quarter of its
  intervals: a log's own clock) is thinned instead: from its first epoch on, each next row is
  its first epoch at least 0.95 / ``rate_hz`` after the last row (0.0475 s at 20 Hz), so an
  output at 20 Hz on the log's clock (the graph smoothers' 0.0498 s on a phone log) keeps
  every epoch and a 100 Hz filter keeps every fifth.
- ``csv_table(table)``: the Parquet table (SI, radians) with every angle in degrees: the
  columns ``*_rad`` become ``*_deg`` and ``*_radps`` become ``*_degps``; all others unchanged.
- ``csv_metadata(...)``: the CSV's side file ``<file>.csv-metadata.json`` in the W3C "CSV on
  the Web" vocabulary (https://www.w3.org/TR/tabular-metadata/): what the file holds (final
  or online answer, or the truth), the drive, the height datum, the time reference, the
  tangent-plane origin, the row rate, and each column's unit (``schema:unitText``) and meaning.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

# the default export rate [Hz]: the graph smoothers' output rate (``GraphConfig.output_rate_hz``)
EXPORT_RATE_HZ = 20.0

# clock values such as k·0.005 s land within this fraction of an interval of a grid time
_GRID_TOL = 1e-6
# a track keeps its on-grid epochs when they fill at least this share of its intervals
_ON_GRID_SHARE = 0.25
# off the grid: the least spacing of the rows, in grid intervals
_MIN_SPACING = 0.95

# what each kind of answer is (``Track.answer``), said in every exported file
ANSWERS = {
    "final": "final trajectory: the estimator's answer after the whole drive (a smoother's "
             "smoothed trajectory, a filter's forward pass)",
    "online": "online (real-time) estimate: each epoch's state right after its own update, "
              "computed from the data up to that epoch only",
    "truth": "truth of the simulated drive",
}


def at_rate(table: pd.DataFrame, rate_hz: float | None) -> pd.DataFrame:
    """The rows of ``table`` (column ``t_s`` [s], increasing) on the grid t = k / ``rate_hz``
    of the drive clock (module docstring): its epochs on the grid, or, when those fill under
    a quarter of the intervals [k / rate_hz, (k + 1) / rate_hz) it spans, its epochs thinned
    to at least 0.95 / ``rate_hz`` apart. ``rate_hz=None`` returns ``table`` unchanged."""
    if rate_hz is None or len(table) < 2:
        return table
    t = table["t_s"].to_numpy()
    x = t * float(rate_hz)  # time in grid intervals
    k = np.floor(x + _GRID_TOL)
    first = np.r_[True, k[1:] != k[:-1]]  # the first epoch of each interval
    on_grid = first & (np.abs(x - k) <= _GRID_TOL)
    if np.count_nonzero(on_grid) >= _ON_GRID_SHARE * np.count_nonzero(first):
        return table[on_grid].reset_index(drop=True)
    keep, i, step = [], 0, _MIN_SPACING / float(rate_hz)
    while i < t.size:  # one pass per kept row
        keep.append(i)
        i = int(np.searchsorted(t, t[i] + step, side="left"))
    return table.iloc[keep].reset_index(drop=True)


def rate_note(rate_hz: float | None) -> str:
    """One sentence on the rows of an export at ``rate_hz`` (None: every epoch)."""
    if rate_hz is None:
        return "rows: every epoch of the estimate"
    return (f"rows: the epochs on the {rate_hz:g} Hz grid of the drive clock (t a multiple of "
            f"{1.0 / rate_hz:g} s; a track without epochs on the grid: its epochs at least "
            f"{_MIN_SPACING / rate_hz:g} s apart) ('vnav-graph export --full-rate': every "
            "epoch)")


def csv_name(column: str) -> str:
    """The CSV's name of a Parquet column: angles in degrees (``*_rad`` → ``*_deg``,
    ``*_radps`` → ``*_degps``)."""
    if column.endswith("_rad"):
        return column[: -len("_rad")] + "_deg"
    if column.endswith("_radps"):
        return column[: -len("_radps")] + "_degps"
    return column


def csv_table(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with every angle column in degrees under its ``csv_name``."""
    out = {}
    for c in table.columns:
        v = table[c].to_numpy()
        out[csv_name(c)] = np.degrees(v) if csv_name(c) != c else v
    return pd.DataFrame(out)


# unit of a CSV column, by its name's suffix
_UNITS = (("_mps2", "m/s^2"), ("_degps", "deg/s"), ("_mps", "m/s"), ("_deg", "deg"),
          ("_m", "m"), ("_s", "s"))


def column_unit(name: str) -> str:
    """The unit of a CSV column ("1" for the dimensionless baro scale)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return "1"


_AXES = {"n": "north", "e": "east", "d": "down", "x": "body x", "y": "body y", "z": "body z"}


def column_meaning(name: str, height_datum: str) -> str:
    """What a CSV column holds (without its unit)."""
    fixed = {
        "t_s": "time on the drive's clock",
        "lat_deg": "WGS-84 geodetic latitude",
        "lon_deg": "WGS-84 geodetic longitude",
        "alt_m": f"height, +up: {height_datum}",
        "roll_deg": "roll: z-y-x Euler angle of the body-to-NED rotation",
        "pitch_deg": "pitch: z-y-x Euler angle of the body-to-NED rotation",
        "yaw_deg": "yaw (heading from north): z-y-x Euler angle of the body-to-NED rotation",
        "baro_bias_m": "barometer Gauss-Markov bias b(t)",
        "baro_scale": "barometer scale-factor error (whole-drive calibration)",
        "baro_latency_s": "barometer latency (whole-drive calibration)",
        "horiz_sd_m": "one-sigma horizontal position error, sqrt(pos_n_sd^2 + pos_e_sd^2)",
        "alt_sd_m": "one-sigma of alt_m (down-position sigma)",
        "baro_scale_sd": "one-sigma of the barometer scale-factor error",
        "baro_latency_sd_s": "one-sigma of the barometer latency",
        "baro_bias_sd_m": "one-sigma of baro_bias_m",
    }
    if name in fixed:
        return fixed[name]
    parts = name.split("_")
    if name.startswith("pos_") and parts[1] in _AXES:
        what = f"local tangent-plane {_AXES[parts[1]]} position from the drive's origin"
    elif name.startswith("vel_") and parts[1] in _AXES:
        what = f"{_AXES[parts[1]]} velocity (NED)"
    elif name.startswith("att_") and parts[1] in _AXES:
        what = f"tilt (attitude) error about the {_AXES[parts[1]]} axis"
    elif name.startswith(("bias_gyro_", "bias_accel_")) and parts[2] in _AXES:
        what = f"{parts[1].replace('accel', 'accelerometer').replace('gyro', 'gyroscope')} " \
               f"bias, {_AXES[parts[2]]} axis"
    else:
        return name
    return f"one-sigma of the {what}" if "_sd_" in name else what


def csv_metadata(file_name: str, columns: list[str], title: str, answer: str,
                 notes: list[str], creator: str, height_datum: str) -> dict[str, Any]:
    """The CSV on the Web description of the CSV ``file_name`` (module docstring)."""
    return {
        "@context": "http://www.w3.org/ns/csvw",
        "url": file_name,
        "dc:title": title,
        "dc:description": ANSWERS[answer],
        "dc:creator": creator,
        "rdfs:comment": notes,
        "dialect": {"header": True, "headerRowCount": 1, "delimiter": ","},
        "tableSchema": {"columns": [
            {"name": c, "titles": c, "datatype": "double", "null": "",
             "schema:unitText": column_unit(c),
             "dc:description": f"{column_meaning(c, height_datum)} [{column_unit(c)}]"}
            for c in columns]},
    }
