"""SO(3) and quaternion kernels shared by the strapdown, the EKF, the AHRS and the graph.

All are numba ``njit`` functions on single vectors (callable from other kernels and from
Python); ``vnav_graph.geo.frames`` holds the vectorised numpy versions for whole trajectories
(``skew``, ``rph_to_quat``), tested equal to these. Conventions (docs/design.md): quaternions
scalar first (w, x, y, z); ``q_nb`` maps body vectors into n; roll-pitch-yaw are z-y-x Euler
angles, q = q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def cross3(a, b):
    """a × b for 3-vectors."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def skew3(v):
    """Cross-product matrix [v×] (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def quat_mul(p, q):
    """Hamilton product p ⊗ q."""
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ])


@njit(cache=True)
def quat_exp(phi):
    """Quaternion of the rotation vector φ (series below 1e-8 rad)."""
    a = np.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    if a < 1e-8:
        s = 0.5 - a * a / 48.0
        c = 1.0 - a * a / 8.0
    else:
        s = np.sin(0.5 * a) / a
        c = np.cos(0.5 * a)
    return np.array([c, s * phi[0], s * phi[1], s * phi[2]])


@njit(cache=True)
def quat_to_dcm_into(q, c):
    """Rotation matrix of a unit quaternion written into ``c`` (a (3, 3) array or view),
    without allocating; ``quat_to_dcm`` returns a new one."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c[0, 0] = 1 - 2 * (y * y + z * z)
    c[0, 1] = 2 * (x * y - w * z)
    c[0, 2] = 2 * (x * z + w * y)
    c[1, 0] = 2 * (x * y + w * z)
    c[1, 1] = 1 - 2 * (x * x + z * z)
    c[1, 2] = 2 * (y * z - w * x)
    c[2, 0] = 2 * (x * z - w * y)
    c[2, 1] = 2 * (y * z + w * x)
    c[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def quat_to_dcm(q):
    """Rotation matrix of a unit quaternion (C_nb of q_nb)."""
    c = np.empty((3, 3))
    quat_to_dcm_into(q, c)
    return c


@njit(cache=True)
def dcm_to_quat(c):
    """Unit quaternion (w ≥ 0) of a rotation matrix (Shepperd: the largest of 1 + tr, 1 + 2c_ii
    − tr under the square root, so no branch loses precision); the inverse of ``quat_to_dcm``."""
    q = np.empty(4)
    dcm_to_quat_into(c, q)
    return q


@njit(cache=True)
def dcm_to_quat_into(c, q):
    """``dcm_to_quat`` written into ``q`` (a (4,) array or view), without allocating."""
    tr = c[0, 0] + c[1, 1] + c[2, 2]
    if tr >= c[0, 0] and tr >= c[1, 1] and tr >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 + tr)
        q[0] = 0.25 * s
        q[1] = (c[2, 1] - c[1, 2]) / s
        q[2] = (c[0, 2] - c[2, 0]) / s
        q[3] = (c[1, 0] - c[0, 1]) / s
    elif c[0, 0] >= c[1, 1] and c[0, 0] >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 + 2.0 * c[0, 0] - tr)
        q[0] = (c[2, 1] - c[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (c[0, 1] + c[1, 0]) / s
        q[3] = (c[0, 2] + c[2, 0]) / s
    elif c[1, 1] >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 + 2.0 * c[1, 1] - tr)
        q[0] = (c[0, 2] - c[2, 0]) / s
        q[1] = (c[0, 1] + c[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (c[1, 2] + c[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + 2.0 * c[2, 2] - tr)
        q[0] = (c[1, 0] - c[0, 1]) / s
        q[1] = (c[0, 2] + c[2, 0]) / s
        q[2] = (c[1, 2] + c[2, 1]) / s
        q[3] = 0.25 * s
    sign = -1.0 if q[0] < 0.0 else 1.0
    norm = np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    for i in range(4):
        q[i] = sign * q[i] / norm


@njit(cache=True)
def so3_exp(phi):
    """Rotation matrix exp([φ×]) (Rodrigues; second-order series below 1e-9 rad)."""
    out = np.empty((3, 3))
    so3_exp_into(phi, out)
    return out


@njit(cache=True)
def so3_exp_into(phi, out):
    """``so3_exp`` written into ``out`` (a (3, 3) array or view), without allocating:
    I + (sin a / a)[φ×] + ((1 − cos a)/a²)[φ×]², a = |φ|, with [φ×]² = φφᵀ − a²I."""
    a2 = phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2
    a = np.sqrt(a2)
    if a < 1e-9:
        s1, s2 = 1.0, 0.5
    else:
        s1, s2 = np.sin(a) / a, (1.0 - np.cos(a)) / a2
    for i in range(3):
        for j in range(3):
            out[i, j] = s2 * phi[i] * phi[j]
        out[i, i] += 1.0 - s2 * a2
    out[0, 1] -= s1 * phi[2]
    out[0, 2] += s1 * phi[1]
    out[1, 0] += s1 * phi[2]
    out[1, 2] -= s1 * phi[0]
    out[2, 0] -= s1 * phi[1]
    out[2, 1] += s1 * phi[0]


@njit(cache=True)
def rpy_quat(roll, pitch, yaw):
    """q_nb of roll, pitch, yaw [rad]: q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ), closed form."""
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


@njit(cache=True)
def yaw_of(q):
    """Yaw ψ [rad] of q_nb (z-y-x Euler angles)."""
    return np.arctan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] ** 2 + q[3] ** 2))
