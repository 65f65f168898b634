"""Forward/backward two-filter smoothing of a linear-Gaussian model, the reference for the
separation of ``ekf-rts`` (``ekf.backward``).

Model: x_{k+1} = F x_k + w, w ~ N(0, Q); z_k = H x_k + v, v ~ N(0, R); x_0 ~ N(m0, P0).
The forward Kalman filter gives x̂_k|k, P_k|k. The backward information filter runs from the
last epoch with no prior (information Y = 0) and gives, at each k, the information of the
measurements k+1 … N alone about x_k: (y_k, Y_k), predicted backward through
x_k = F⁻¹ (x_{k+1} − w). The two are independent given x_k, so the smoothed estimate is their
product (Fraser & Potter 1969):
    P_s = (P_k|k⁻¹ + Y_k)⁻¹,   x_s = P_s (P_k|k⁻¹ x̂_k|k + y_k),
which equals the Rauch-Tung-Striebel smoother's x̂_k|N, P_k|N (``rts``) exactly in exact
arithmetic. ``tests/unit/test_two_filter.py`` checks that equality.
"""

from __future__ import annotations

import numpy as np

from ...types.streams import FloatArray


def kalman(f: FloatArray, q: FloatArray, h: FloatArray, r: FloatArray, z: FloatArray,
           m0: FloatArray, p0: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Forward filter: x̂_k|k (N, n) and P_k|k (N, n, n) for measurements z (N, m)."""
    n = m0.size
    xs, ps = np.empty((z.shape[0], n)), np.empty((z.shape[0], n, n))
    x, p = m0.copy(), p0.copy()
    for k in range(z.shape[0]):
        if k > 0:
            x, p = f @ x, f @ p @ f.T + q
        s = h @ p @ h.T + r
        g = np.linalg.solve(s, h @ p).T
        x = x + g @ (z[k] - h @ x)
        p = p - g @ h @ p
        xs[k], ps[k] = x, 0.5 * (p + p.T)
    return xs, ps


def rts(f: FloatArray, q: FloatArray, xf: FloatArray, pf: FloatArray
        ) -> tuple[FloatArray, FloatArray]:
    """Rauch-Tung-Striebel smoother over the forward filter's (xf, pf)."""
    xs, ps = xf.copy(), pf.copy()
    for k in range(xf.shape[0] - 2, -1, -1):
        pm = f @ pf[k] @ f.T + q
        g = np.linalg.solve(pm, f @ pf[k]).T
        xs[k] = xf[k] + g @ (xs[k + 1] - f @ xf[k])
        ps[k] = pf[k] + g @ (ps[k + 1] - pm) @ g.T
    return xs, ps


def backward_information(f: FloatArray, q: FloatArray, h: FloatArray, r: FloatArray,
                         z: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Backward information filter without prior: (y_k, Y_k), the information of the
    measurements after k about x_k, for every k (N, n) and (N, n, n); zero at the last."""
    nz, n = z.shape[0], f.shape[0]
    ys, yy = np.zeros((nz, n)), np.zeros((nz, n, n))
    ri = np.linalg.inv(r)
    y, ym = np.zeros(n), np.zeros((n, n))
    for k in range(nz - 1, 0, -1):
        # measurement k, then back through the dynamics to k − 1:
        # x_k = F x_{k−1} + w  ⇒  Y_{k−1} = Fᵀ (Y⁻ − Y⁻ (Y⁻ + Q⁻¹)⁻¹ Y⁻) F, written as
        # Fᵀ (I + Y⁻ Q)⁻¹ Y⁻ F (valid for singular Y⁻)
        y = y + h.T @ ri @ z[k]
        ym = ym + h.T @ ri @ h
        a = np.linalg.inv(np.eye(n) + ym @ q)
        y, ym = f.T @ a @ y, f.T @ a @ ym @ f
        ym = 0.5 * (ym + ym.T)
        ys[k - 1], yy[k - 1] = y, ym
    return ys, yy


def combine(xf: FloatArray, pf: FloatArray, yb: FloatArray, ybb: FloatArray
            ) -> tuple[FloatArray, FloatArray]:
    """Two-filter smoother: the product of the forward Gaussian and the backward information
    at every epoch (module docstring)."""
    xs, ps = np.empty_like(xf), np.empty_like(pf)
    for k in range(xf.shape[0]):
        info = np.linalg.inv(pf[k])
        ps[k] = np.linalg.inv(info + ybb[k])
        xs[k] = ps[k] @ (info @ xf[k] + yb[k])
    return xs, ps
