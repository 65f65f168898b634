"""What ``run`` writes beside its estimates so that a run folder can be exported later.

``drive.json`` (``DRIVE_INFO``): the drive's tangent-plane origin, height datum, time
reference and GNSS gaps; ``truth.parquet`` (``TRUTH_TABLE``): the truth trajectory in the
estimates' table layout (``Estimate.to_dataframe``), where the drive has one.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..types import Drive, Estimate

DRIVE_INFO = "drive.json"
TRUTH_TABLE = "truth.parquet"
SCHEMA = "vnav_graph.drive_info/1"

# a GNSS gap worth a placemark: a logging gap (``nav.gaps``' rule) of at least this long
GAP_MIN_S = 2.0

def gnss_gaps(t: np.ndarray) -> list[list[float]]:
    """Intervals [s] between consecutive fixes that are logging gaps by the shared rule
    (``nav.gaps.imu_gaps``: over 5 × the median interval) and last over ``GAP_MIN_S``."""
    from ..nav.gaps import imu_gaps

    return [[float(t[i]), float(t[i + 1])] for i in imu_gaps(t) if t[i + 1] - t[i] > GAP_MIN_S]


def drive_info(drive: Drive) -> dict[str, Any]:
    """The ``drive.json`` document of ``drive`` (module docstring)."""
    meta = drive.meta
    t0 = meta.get("t0_unix_s")
    lat, lon, h = (float(v) for v in drive.origin_lla)
    return {
        "schema": SCHEMA,
        "name": drive.name,
        "source": drive.source,
        "origin_lla": {"lat_deg": float(np.degrees(lat)), "lon_deg": float(np.degrees(lon)),
                       "height_m": h},
        "height_reference": drive.height_reference,
        "height_datum": drive.height_datum,
        "t0_unix_s": None if t0 is None else float(t0),
        "time_reference": ("t_s is seconds on the drive's clock; t0_unix_s is the Unix time "
                           "[s, UTC] of t_s = 0" if t0 is not None else
                           "t_s is seconds on the drive's clock; the drive has no absolute "
                           "time"),
        "t_span_s": [float(drive.imu.t[0]), float(drive.imu.t[-1])],
        "gnss_gaps_s": [] if drive.gnss is None else gnss_gaps(drive.gnss.t),
    }


def write_run_info(tmp: Path, summary: dict[str, Any], results: Sequence[Any],
                   drive: Drive) -> None:
    """``run``'s writer for ``drive.json`` and, where the drive has a truth, ``truth.parquet``
    (same call as the other extra writers of ``pipeline.write_outputs``)."""
    (tmp / DRIVE_INFO).write_text(json.dumps(drive_info(drive), indent=1) + "\n")
    if drive.truth is not None:
        provides = frozenset({"alt", "vel_d", "pos_h", "vel_h"}
                             | ({"att"} if drive.truth.q_nb is not None else set()))
        truth = Estimate(estimator="truth", trajectory=drive.truth, provides=provides)
        truth.to_dataframe(drive.origin_lla).to_parquet(tmp / TRUTH_TABLE, index=False)
