"""WGS-84 Earth model: radii of curvature, normal gravity, Earth rate, transport rate.

References: NIMA TR8350.2 (WGS-84, 3rd ed.); Groves, *Principles of GNSS, Inertial and
Multisensor Integrated Navigation Systems*, 2nd ed., §2.4 and §5.4 (eqs. 2.105-2.106, 2.134,
5.44). All functions are vectorised over numpy arrays; latitude in radians, height in metres
above the ellipsoid. The radii and gravity are written once, as plain arithmetic
(``radii_of`` / ``gravity_of``), run by numpy over arrays (``radii``, ``gravity``) and compiled
by numba for scalars in the mechanisation hot loops (``radii_scalar``, ``gravity_scalar``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

A = 6378137.0  # semi-major axis [m]
F = 1.0 / 298.257223563  # flattening
B = A * (1.0 - F)  # semi-minor axis [m]
E2 = F * (2.0 - F)  # first eccentricity squared
OMEGA_IE = 7.292115e-5  # Earth rotation rate [rad/s]
GM = 3.986004418e14  # [m^3/s^2]
GAMMA_E = 9.7803253359  # normal gravity at the equator [m/s^2]
GAMMA_P = 9.8321849378  # normal gravity at the poles [m/s^2]
_K_SOM = (B * GAMMA_P) / (A * GAMMA_E) - 1.0  # Somigliana constant
_M = OMEGA_IE**2 * A**2 * B / GM
G0 = 9.80665  # standard gravity [m/s^2] (ISA, unit conversions only)


def radii_of(lat: Any) -> Any:
    """Meridian R_N and transverse (prime vertical) R_E radii of curvature [m] (Groves 2.105-6)
    of a float or float array ``lat`` [rad]: the formula, for numpy and numba alike."""
    s2 = np.sin(lat) ** 2
    w = np.sqrt(1.0 - E2 * s2)
    return A * (1.0 - E2) / w**3, A / w


def radii(lat: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Meridian R_N and transverse (prime vertical) R_E radii of curvature [m] (Groves 2.105-6)."""
    return radii_of(np.asarray(lat, dtype=float))


def gravity_of(lat: Any, h: Any) -> Any:
    """Normal gravity γ(lat, h) [m/s²] of floats or float arrays: the formula of ``gravity``,
    for numpy and numba alike."""
    s2 = np.sin(lat) ** 2
    g_surf = GAMMA_E * (1.0 + _K_SOM * s2) / np.sqrt(1.0 - E2 * s2)
    return g_surf * (1.0 - 2.0 / A * (1.0 + F + _M - 2.0 * F * s2) * h + 3.0 / A**2 * h**2)


def gravity(lat: ArrayLike, h: ArrayLike) -> NDArray[np.float64]:
    """WGS-84 normal gravity magnitude γ(lat, h) [m/s^2], gravitation plus centrifugal.

    Somigliana's formula on the ellipsoid and the second-order free-air height correction
    (TR8350.2 eqs. 4-1 and 4-3). Directed along the ellipsoidal normal (the small north
    component, < 1e-5 m/s^2 below 10 km, is neglected everywhere in the package).
    """
    return gravity_of(np.asarray(lat, dtype=float), np.asarray(h, dtype=float))


def earth_rate_n(lat: ArrayLike) -> NDArray[np.float64]:
    """Earth rotation rate resolved in local NED, shape (..., 3) [rad/s]."""
    lat = np.asarray(lat, dtype=float)
    return np.stack(
        [OMEGA_IE * np.cos(lat), np.zeros_like(lat), -OMEGA_IE * np.sin(lat)], axis=-1
    )


def transport_rate_n(lat: ArrayLike, h: ArrayLike, vel_n: ArrayLike) -> NDArray[np.float64]:
    """Transport rate ω_en^n of local NED, shape (..., 3) [rad/s] (Groves eq. 5.44)."""
    lat = np.asarray(lat, dtype=float)
    h = np.asarray(h, dtype=float)
    v = np.asarray(vel_n, dtype=float)
    rn, re = radii(lat)
    return np.stack(
        [
            v[..., 1] / (re + h),
            -v[..., 0] / (rn + h),
            -v[..., 1] * np.tan(lat) / (re + h),
        ],
        axis=-1,
    )


# the same formulas compiled for scalars (the mechanisation hot loops)
radii_scalar = njit(cache=True)(radii_of)
gravity_scalar = njit(cache=True)(gravity_of)
