"""Frames and rotations: lla <-> tangent-plane NED (pymap3d's WGS-84 formulas), quaternions,
Euler angles.

Quaternions are scalar-first ``(w, x, y, z)``, Hamilton; ``q_ab`` maps b-coordinates into a.
Euler angles are roll, pitch, yaw (z-y-x, aerospace): ``mat_nb = Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

from functools import cache
from math import pi

import numpy as np
import pymap3d
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]


def lla_to_ned(lla: ArrayLike, origin_lla: ArrayLike) -> FloatArray:
    """Geodetic (rad, rad, m) to tangent-plane NED at ``origin_lla`` [m], shape (N, 3)."""
    a = np.atleast_2d(np.asarray(lla, dtype=float))
    o = np.asarray(origin_lla, dtype=float)
    n, e, d = pymap3d.geodetic2ned(a[:, 0], a[:, 1], a[:, 2], o[0], o[1], o[2], deg=False)
    return np.column_stack([n, e, d])


def ned_to_lla(pos_n: ArrayLike, origin_lla: ArrayLike) -> FloatArray:
    """Tangent-plane NED at ``origin_lla`` [m] to geodetic (rad, rad, m), shape (N, 3).

    pymap3d's ``ned2geodetic`` (WGS-84; You 2000, no iteration), the same operations in the
    same order, so bitwise equal to it (tests/unit/test_frames_fast.py), without its
    per-call overhead (0.3 ms, most of the cost for the few points a graph-isam2 update
    converts); the origin's terms are computed once. Points at the Earth's centre or on its
    axis go through pymap3d itself."""
    p = np.atleast_2d(np.asarray(pos_n, dtype=float))
    o = np.asarray(origin_lla, dtype=float)
    x0, y0, z0, clat, slat, clon, slon = _origin_terms(float(o[0]), float(o[1]), float(o[2]))
    north, east, up = p[:, 0], p[:, 1], -p[:, 2]
    # pymap3d.enu2uvw, then enu2ecef
    t = clat * up - slat * north
    w = slat * up + clat * north
    x = x0 + (clon * t - slon * east)
    y = y0 + (slon * t + clon * east)
    z = z0 + w
    out = _ecef_to_lla(x, y, z)
    if out is None:
        lat, lon, h = pymap3d.ned2geodetic(p[:, 0], p[:, 1], p[:, 2], o[0], o[1], o[2],
                                           deg=False)
        return np.column_stack([lat, lon, h])
    return np.column_stack(out)


_WGS84_A, _WGS84_B = 6378137.0, 6356752.31424518  # pymap3d's Ellipsoid "wgs84"


@cache
def _origin_terms(lat0: float, lon0: float, h0: float) -> tuple[np.float64, ...]:
    """pymap3d.geodetic2ecef of the origin and the sines and cosines of its lat, lon."""
    lat, lon, alt = np.float64(lat0), np.float64(lon0), np.float64(h0)
    a, b = _WGS84_A, _WGS84_B
    n = a**2 / np.hypot(a * np.cos(lat), b * np.sin(lat))
    x0 = (n + alt) * np.cos(lat) * np.cos(lon)
    y0 = (n + alt) * np.cos(lat) * np.sin(lon)
    z0 = (n * (b / a) ** 2 + alt) * np.sin(lat)
    return x0, y0, z0, np.cos(lat), np.sin(lat), np.cos(lon), np.sin(lon)


def _ecef_to_lla(x: FloatArray, y: FloatArray, z: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """pymap3d.ecef2geodetic (WGS-84, radians) for arrays; None where it would take its
    special branch (a point at the centre or on the polar axis)."""
    a, b = _WGS84_A, _WGS84_B
    r = np.sqrt(x**2 + y**2 + z**2)
    e = np.sqrt(a**2 - b**2)
    u = np.sqrt(0.5 * (r**2 - e**2) + 0.5 * np.hypot(r**2 - e**2, 2 * e * z))
    hxy = np.hypot(x, y)
    hue = np.hypot(u, e)
    if np.any((np.abs(u) <= 1e-8) | (np.abs(hxy) <= 1e-8)):  # np.isclose(·, 0)
        return None
    beta = np.arctan(hue / u * z / hxy)
    beta += ((b * u - a * hue + e**2) * np.sin(beta)) / (
        a * hue * 1 / np.cos(beta) - e**2 * np.cos(beta))
    lat = np.arctan(a / b * np.tan(beta))
    lim_pi2 = pi / 2 - np.finfo(beta.dtype).eps
    lat = np.where(beta >= lim_pi2, pi / 2, lat)
    lat = np.where(beta <= -lim_pi2, -pi / 2, lat)
    lon = np.arctan2(y, x)
    cos_beta = np.cos(beta)
    cos_beta = np.where(beta >= lim_pi2, 0, cos_beta)
    cos_beta = np.where(beta <= -lim_pi2, 0, cos_beta)
    alt = np.hypot(z - b * np.sin(beta), hxy - a * cos_beta)
    inside = x**2 / a**2 + y**2 / a**2 + z**2 / b**2 < 1
    if inside.any():
        alt[inside] = -alt[inside]
    return lat, lon, alt


def skew(v: ArrayLike) -> FloatArray:
    """Cross-product matrix [v×], shape (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], -1),
            np.stack([v[..., 2], z, -v[..., 0]], -1),
            np.stack([-v[..., 1], v[..., 0], z], -1),
        ],
        -2,
    )


def rph_to_quat(rph: ArrayLike) -> FloatArray:
    """Roll, pitch, yaw [rad] (N, 3) to q_nb (N, 4) scalar first."""
    r = np.atleast_2d(np.asarray(rph, dtype=float))
    rot = Rotation.from_euler("ZYX", r[:, ::-1])
    return _canon(rot.as_quat(scalar_first=True))


def quat_to_rph(q_nb: ArrayLike) -> FloatArray:
    """q_nb (N, 4) to roll, pitch, yaw [rad] (N, 3)."""
    rot = Rotation.from_quat(np.atleast_2d(q_nb), scalar_first=True)
    return rot.as_euler("ZYX")[:, ::-1]


def quat_to_mat(q_nb: ArrayLike) -> FloatArray:
    """q_nb (..., 4) to mat_nb (..., 3, 3)."""
    q = np.asarray(q_nb, dtype=float)
    return Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_matrix().reshape(
        q.shape[:-1] + (3, 3)
    )


def mat_to_quat(mat_nb: ArrayLike) -> FloatArray:
    m = np.asarray(mat_nb, dtype=float)
    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat(scalar_first=True)
    return _canon(q).reshape(m.shape[:-2] + (4,))


def slerp_quat(t: ArrayLike, q: ArrayLike, t_query: ArrayLike) -> FloatArray:
    """Spherical linear interpolation of q (N, 4) given at t (N,) to t_query (M,).

    Queries that fall on a knot take its (normalised) quaternion directly: evaluating ten
    estimates at the truth's own epochs then builds no ``Slerp`` (~0.1 s per 24,000 knots)."""
    t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
    tq0 = np.asarray(t_query, dtype=float)
    tq = np.atleast_1d(tq0)
    k = np.clip(np.searchsorted(t, tq), 0, max(t.size - 1, 0))
    on_knot = t[k] == tq if t.size else np.zeros(tq.shape, dtype=bool)
    out = np.empty((tq.size, 4))
    qk = q[k[on_knot]]
    out[on_knot] = qk / np.linalg.norm(qk, axis=1, keepdims=True)
    if not on_knot.all():
        if t.size < 2:
            raise ValueError("slerp_quat: at least 2 knots are needed between knots")
        # scipy's Slerp on the bracketing knots only: building it on every knot costs
        # ~200 bytes per knot (144 MB for a 1-hour 200 Hz truth) for a few thousand queries
        tm = tq[~on_knot]
        i = np.clip(np.searchsorted(t, tm) - 1, 0, t.size - 2)
        r0 = Rotation.from_quat(q[i], scalar_first=True)
        step = (r0.inv() * Rotation.from_quat(q[i + 1], scalar_first=True)).as_rotvec()
        alpha = (tm - t[i]) / (t[i + 1] - t[i])
        out[~on_knot] = (r0 * Rotation.from_rotvec(step * alpha[:, None])).as_quat(
            scalar_first=True)
    return _canon(out[0] if tq0.ndim == 0 else out)


def attitude_error_n(q_est: ArrayLike, q_true: ArrayLike) -> FloatArray:
    """Small-angle attitude error ψ resolved in n, (N, 3) [rad]: C_est = exp([ψ×]) C_true."""
    r = Rotation.from_quat(np.asarray(q_est), scalar_first=True) * Rotation.from_quat(
        np.asarray(q_true), scalar_first=True
    ).inv()
    return r.as_rotvec()


def _canon(q: FloatArray) -> FloatArray:
    """Sign convention w >= 0 so stored quaternions are unique."""
    return np.where(q[..., :1] < 0, -q, q)
