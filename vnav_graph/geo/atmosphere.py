"""International Standard Atmosphere (ISO 2533 / ICAO), pressure <-> altitude.

Troposphere (0-11 km, lapse L = 6.5 K/km) and lower stratosphere (11-20 km, isothermal).
Heights are geopotential; the package treats them as heights above mean sea level and folds
the geoid undulation into the baro bias.

Non-standard days are modelled with a temperature offset ``dT`` (ISA+dT, same lapse) and a
sea-level pressure ``p0``. A barometric altimeter always converts pressure with the *standard*
law, so a real atmosphere produces
  - a scale-factor error ≈ dT / T0 ≈ 0.35 %/K of altitude above the reference, and
  - a bias ≈ -(RT/gp)·Δp0 ≈ 8.3 m/hPa near sea level.
Both are derived in ``baro_error_from_atmosphere``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

P0 = 101325.0  # standard sea-level pressure [Pa]
T0 = 288.15  # standard sea-level temperature [K]
L = 0.0065  # tropospheric lapse rate [K/m]
R_AIR = 287.05287  # specific gas constant of dry air [J/(kg K)]
G0 = 9.80665  # [m/s^2]
H_TROP = 11000.0  # tropopause [m]
H_MAX = 20000.0  # upper validity limit [m]
_EXP = G0 / (R_AIR * L)  # ≈ 5.2559


def isa_pressure(
    alt: ArrayLike, dT: float = 0.0, p0: float = P0
) -> NDArray[np.float64]:
    """Static pressure [Pa] at altitude ``alt`` [m] in an ISA+dT atmosphere with sea-level
    pressure ``p0`` [Pa]. Valid for -1 km .. 20 km."""
    h = np.asarray(alt, dtype=float)
    if np.any(h > H_MAX) or np.any(h < -1000.0):
        raise ValueError("isa_pressure: altitude outside -1000 .. 20000 m")
    t_sl = T0 + dT
    t_trop = t_sl - L * H_TROP
    p_trop = p0 * (t_trop / t_sl) ** _EXP
    below = p0 * (1.0 - L * np.minimum(h, H_TROP) / t_sl) ** _EXP
    above = p_trop * np.exp(-G0 * (h - H_TROP) / (R_AIR * t_trop))
    return np.where(h <= H_TROP, below, above)


def isa_altitude(
    pressure: ArrayLike, dT: float = 0.0, p0: float = P0
) -> NDArray[np.float64]:
    """Inverse of ``isa_pressure``: altitude [m] from static pressure [Pa]."""
    p = np.asarray(pressure, dtype=float)
    if np.any(p <= 0):
        raise ValueError("isa_altitude: pressure must be positive [Pa]")
    t_sl = T0 + dT
    t_trop = t_sl - L * H_TROP
    p_trop = p0 * (t_trop / t_sl) ** _EXP
    below = t_sl / L * (1.0 - (np.maximum(p, p_trop) / p0) ** (1.0 / _EXP))
    above = H_TROP + R_AIR * t_trop / G0 * np.log(p_trop / np.minimum(p, p_trop))
    return np.where(p >= p_trop, below, above)


def isa_temperature(alt: ArrayLike, dT: float = 0.0) -> NDArray[np.float64]:
    """Static temperature [K] at altitude [m]."""
    h = np.asarray(alt, dtype=float)
    return T0 + dT - L * np.minimum(h, H_TROP)


def baro_error_from_atmosphere(
    alt_ref: float, dT: float, p0: float = P0
) -> tuple[float, float]:
    """Linearised altimeter error produced by a non-standard atmosphere near ``alt_ref``.

    Returns ``(scale, bias_m)`` such that ``isa_altitude(isa_pressure(h, dT, p0)) ≈
    (1 + scale)·(h - alt_ref) + alt_ref + bias_m`` for h close to ``alt_ref``: the
    derivative and the offset at ``alt_ref`` (central difference over ±50 m).
    """
    dh = 50.0
    hs = np.array([alt_ref - dh, alt_ref, alt_ref + dh])
    hb = isa_altitude(isa_pressure(hs, dT, p0))
    scale = (hb[2] - hb[0]) / (2 * dh) - 1.0
    return float(scale), float(hb[1] - alt_ref)
