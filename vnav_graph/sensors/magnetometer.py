"""Magnetometer: the heading measurement model shared by the EKF and the graph smoothers.

A three-axis magnetometer in body axes b (forward-right-down) measures

    z = C_nbᵀ m_n + b_m + n,   n ~ N(0, σ_m² I)

with m_n the Earth's field in the local-level frame n (north-east-down, World Magnetic
Model, :mod:`vnav_graph.geo.magfield`), b_m the hard-iron bias (the vehicle's own field, a
state of the estimators) and σ_m the noise per axis [µT].

Only the **heading** is used. The field's strength on a vehicle is unreliable (soft iron,
motor currents, a logger's unknown scale; docs/real_logs.md, "Magnetometer noise, field
strength and spread"), and its vertical component would pull roll and pitch, which the vertical
channel depends on. The bias-corrected body field is rotated into n with the *estimated*
attitude; its horizontal azimuth

    a = atan2(m̂_E, m̂_N),   m̂_n = C_nb (z − b_m)

equals the magnetic declination D when the attitude and b_m are right. The measurement is
a − D (wrapped to ±π), predicted 0, with σ_a = √(σ_m² + σ_floor² H²) / H, H the measured
horizontal field (σ_floor: the heading error floor for declination and soft-iron errors).

Jacobians of a with respect to m̂_n (the gradient of atan2): g = (−m̂_E, m̂_N, 0)/H². The
estimators chain it with their own attitude error:

- EKF, tilt error ψ in n with C̃ = (I + [ψ×]) C: ∂m̂_n/∂ψ = −[m̂_n×], ∂a/∂ψ = −g [m̂_n×];
  the yaw component is exactly 1, the tilt components are −m̂_N m̂_D/H², −m̂_E m̂_D/H²
  (at a dip of 65° a tilt error moves the heading 2.1× as much);
- graph, Pose3 retraction R Exp(ω) (ω in b): ∂m̂_n/∂ω = −R [(z − b_m)×];
- both: ∂a/∂b_m = −g C_nb.

The hard-iron bias is separable from the heading only while the vehicle turns: a body-fixed
offset rotates with the vehicle in n, a heading error does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from ..geo.magfield import FieldModel

from ..types import Drive
from ..types.streams import FloatArray, MagStream

MIN_HORIZONTAL_UT = 3.0  # weaker horizontal fields give no usable heading (near the poles) [µT]
# Defaults shared by ekf/ekf-rts (EkfConfig) and both graphs (GraphConfig):
MAG_INTERVAL_S = 1.0  # at most one heading per this many seconds (errors correlated over s)
MAG_HEADING_FLOOR = float(np.radians(2.0))  # heading σ floor: declination, soft iron [rad]
MAG_BIAS_SD_UT = 3.0  # prior σ of each hard-iron component after the log's calibration [µT]
# The Earth's field strength is constant over a drive; a hard-iron offset comparable to it
# makes |z| swing as the vehicle turns. When the interquartile range of |z| exceeds this
# fraction of its median the disturbance is beyond the hard-iron prior (≈ 5 µT of a 50 µT
# field) and the heading is not used: an autopilot's calibrated compass stays well under it, a
# phone next to a car's steel and electrics well over (docs/real_logs.md, "Magnetometer noise,
# field strength and spread").
MAX_FIELD_SPREAD = 0.10


def field_spread(field_b: FloatArray) -> float:
    """Interquartile range of the measured field strength over its median."""
    n = np.linalg.norm(np.asarray(field_b, float), axis=1)
    q25, q50, q75 = np.percentile(n, [25, 50, 75])
    return float((q75 - q25) / q50) if q50 > 0 else float("inf")


def usable(mag: MagStream | None) -> tuple[bool, str]:
    """Whether an estimator should use this ``MagStream`` for heading, and why not."""
    if mag is None:
        return False, ""
    field_b = mag.field_b
    if len(field_b) < 2:
        return False, "magnetometer not used: fewer than 2 samples"
    spread = field_spread(field_b)
    if spread > MAX_FIELD_SPREAD:
        return False, (f"magnetometer not used: its field strength varies by {spread:.0%} "
                       f"(interquartile range over median; > {MAX_FIELD_SPREAD:.0%} means "
                       "vehicle interference beyond the hard-iron model)")
    return True, ""


DEFAULT_YEAR = 2025.0  # date of the field for a drive without one (noted in info)


def drive_field(drive: Drive) -> tuple[FieldModel, str]:
    """The World Magnetic Model's field at the drive's origin on its date
    (``meta["decimal_year"]``), and a note when the drive has no date (``DEFAULT_YEAR``
    used). The one field reference of every estimator that uses the magnetometer."""
    from ..geo.magfield import earth_field

    year = drive.meta.get("decimal_year")
    lat, lon, h = (float(x) for x in drive.origin_lla)
    fm = earth_field(lat, lon, h, float(year) if year is not None else DEFAULT_YEAR)
    note = "" if year is not None else (
        f"drive has no date: declination of the {DEFAULT_YEAR:.1f} field")
    return fm, note


def field_and_info(drive: Drive, use: bool) -> tuple[FieldModel | None, dict[str, Any]]:
    """The field reference an estimator uses (None when it leaves the magnetometer out: not
    wanted, none, or not ``usable``) and what it reports in ``info``: ``mag_note`` (why the
    magnetometer is left out, or that the drive has no date), ``mag_declination_deg`` and
    ``mag_field_model`` when it is used. One function for both families, so ekf and the
    graph say the same thing about the same drive."""
    if not use:
        return None, {}
    ok, why = usable(drive.mag)
    if not ok:
        return None, ({"mag_note": why} if why else {})
    fm, note = drive_field(drive)
    info: dict[str, Any] = {"mag_declination_deg": float(np.degrees(fm.declination_rad)),
                            "mag_field_model": fm.model}
    if note:
        info["mag_note"] = note
    return fm, info


def wrap_pi(a: FloatArray | float) -> FloatArray | float:
    """Angle wrapped to [−π, π)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def heading_sd(sd_ut: float, horizontal_ut: FloatArray | float,
               floor_rad: float) -> FloatArray | float:
    """σ of the field azimuth [rad] for noise σ_m per axis and the horizontal field H [µT]."""
    h = np.asarray(horizontal_ut)
    return np.sqrt((sd_ut / h) ** 2 + floor_rad**2)


@njit(cache=True)
def mag_heading_row(field_b, bias_b, c_nb, declination):  # pragma: no cover - numba
    """The heading model, written once: the azimuth a = atan2(m_E, m_N) of the bias-corrected
    field rotated into n, m = C (z − b_m), against the declination, with its Jacobians in the
    physical errors. The EKF's row calls it at each sample it uses; the graph's heading factor
    (``estimators.graph.model.builtin_sensors``) at each keyframe, chaining ∂r/∂ψ through R.

    Returns (r, h_psi, h_bias, horizontal): r = wrap(a − D) [rad]; h_psi (3,) = ∂a/∂ψ for
    C̃ = (I + [ψ×]) C; h_bias (3,) = ∂a/∂b_m [rad/µT]; horizontal = H [µT].
    """
    d0 = field_b[0] - bias_b[0]
    d1 = field_b[1] - bias_b[1]
    d2 = field_b[2] - bias_b[2]
    mn = c_nb[0, 0] * d0 + c_nb[0, 1] * d1 + c_nb[0, 2] * d2
    me = c_nb[1, 0] * d0 + c_nb[1, 1] * d1 + c_nb[1, 2] * d2
    md = c_nb[2, 0] * d0 + c_nb[2, 1] * d1 + c_nb[2, 2] * d2
    h2 = mn * mn + me * me
    g0 = -me / h2
    g1 = mn / h2
    # −g [m×] with g = (g0, g1, 0): row vector times the skew matrix of m_n
    h_psi = np.empty(3)
    h_psi[0] = -(g1 * md)
    h_psi[1] = -(-g0 * md)
    h_psi[2] = -g0 * me + g1 * mn  # = 1: a yaw error moves the azimuth one for one
    h_bias = np.empty(3)
    for j in range(3):
        h_bias[j] = -(g0 * c_nb[0, j] + g1 * c_nb[1, j])
    r = np.arctan2(me, mn) - declination
    r = (r + np.pi) % (2.0 * np.pi) - np.pi
    return r, h_psi, h_bias, np.sqrt(h2)


# --- the simulated sensor (simulation.measurements.simulate_mag) ---


@dataclass(frozen=True)
class MagSpec:
    """Simulated three-axis magnetometer (scenario TOML section ``[magnetometer]``).

    rate_hz : sample rate [Hz]; samples at 0, 1/rate_hz, … over the truth span
    sd_ut : white noise σ per axis [µT] (also the stream's ``sd_ut``)
    hard_iron_ut : (3,) hard-iron bias in body axes forward-right-down [µT], constant
    year : decimal year of the drive: the World Magnetic Model's epoch (``geo.magfield``)
    """

    rate_hz: float = 10.0
    sd_ut: float = 0.5
    hard_iron_ut: tuple[float, float, float] = (4.0, -3.0, 2.0)
    year: float = 2025.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "hard_iron_ut", tuple(float(x) for x in self.hard_iron_ut))
        if len(self.hard_iron_ut) != 3 or not all(np.isfinite(self.hard_iron_ut)):
            raise ValueError(f"MagSpec.hard_iron_ut: need 3 finite µT values, got "
                             f"{self.hard_iron_ut!r}")
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"MagSpec.rate_hz: must be > 0, got {self.rate_hz!r}")
        if not (np.isfinite(self.sd_ut) and self.sd_ut > 0):
            raise ValueError(f"MagSpec.sd_ut: must be > 0 µT, got {self.sd_ut!r}")
        if not np.isfinite(self.year):
            raise ValueError(f"MagSpec.year: must be a decimal year, got {self.year!r}")
