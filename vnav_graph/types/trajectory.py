"""A navigation trajectory on the drive's clock: a drive's truth or an estimator's answer
(conventions of ``vnav_graph.types``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .checks import as_array, check_shape, check_time

AT_MEMO = 2  # Trajectory.at results kept per trajectory


@dataclass(frozen=True)
class Trajectory:
    """A navigation trajectory (truth or estimate).

    Parameters
    ----------
    t : (N,) [s]
    lla : (N, 3) latitude [rad], longitude [rad], ellipsoidal height [m]. Estimators that
        only estimate the vertical channel set latitude/longitude to NaN (``provides`` says so).
    vel_n : (N, 3) NED velocity [m/s]; NaN north/east for vertical-only estimators.
    q_nb : (N, 4) or None, attitude quaternion (w, x, y, z) mapping b into n.
    bias_gyro, bias_accel : (N, 3) or None [rad/s], [m/s^2]
    bias_baro : (N,) or None, baro Gauss-Markov bias b(t) [m]
    """

    t: NDArray[np.float64]
    lla: NDArray[np.float64]
    vel_n: NDArray[np.float64]
    q_nb: NDArray[np.float64] | None = None
    bias_gyro: NDArray[np.float64] | None = None
    bias_accel: NDArray[np.float64] | None = None
    bias_baro: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        for f in ("t", "lla", "vel_n", "q_nb", "bias_gyro", "bias_accel", "bias_baro"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, as_array(getattr(self, f)))
        check_time("trajectory", self.t)
        n = self.t.size
        check_shape("trajectory.lla", self.lla, (n, 3))
        check_shape("trajectory.vel_n", self.vel_n, (n, 3))
        check_shape("trajectory.q_nb", self.q_nb, (n, 4))
        check_shape("trajectory.bias_gyro", self.bias_gyro, (n, 3))
        check_shape("trajectory.bias_accel", self.bias_accel, (n, 3))
        check_shape("trajectory.bias_baro", self.bias_baro, (n,))
        if not np.all(np.isfinite(self.lla[:, 2])):
            raise ValueError("trajectory.lla: height contains NaN or inf")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def alt(self) -> NDArray[np.float64]:
        """Ellipsoidal height [m, +up]."""
        return self.lla[:, 2]

    @property
    def vel_down(self) -> NDArray[np.float64]:
        return self.vel_n[:, 2]

    def pos_n(self, origin_lla: NDArray[np.float64]) -> NDArray[np.float64]:
        """Tangent-plane NED position relative to ``origin_lla`` [m], shape (N, 3)."""
        from ..geo.frames import lla_to_ned

        return lla_to_ned(self.lla, origin_lla)

    def at(self, t_query: NDArray[np.float64]) -> Trajectory:
        """Interpolate to ``t_query`` (linear; slerp for attitude). Queries must lie inside.

        The last ``AT_MEMO`` results are kept (evaluating ten estimators interpolates the
        truth to the same epochs again and again; the slerp costs ~0.1 s per 24,000 epochs);
        their arrays are read-only."""
        tq = np.asarray(t_query, dtype=float)
        import hashlib

        key = (tq.shape, hashlib.blake2b(np.ascontiguousarray(tq).tobytes(),
                                         digest_size=16).digest())
        memo: dict[Any, Trajectory] = self.__dict__.setdefault("_at_memo", {})
        hit = memo.get(key)
        if hit is None:
            hit = self._interp(tq)
            for a in (hit.t, hit.lla, hit.vel_n, hit.q_nb, hit.bias_gyro, hit.bias_accel,
                      hit.bias_baro):
                if a is not None:
                    a.flags.writeable = False
            while len(memo) >= AT_MEMO:
                memo.pop(next(iter(memo)))
            memo[key] = hit
        return hit

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "_at_memo"}

    def _interp(self, tq: NDArray[np.float64]) -> Trajectory:
        if tq.size and (tq[0] < self.t[0] - 1e-9 or tq[-1] > self.t[-1] + 1e-9):
            raise ValueError("trajectory.at: query times outside the trajectory span")
        tq = np.clip(tq, self.t[0], self.t[-1])  # absorb round-off at the ends

        def lin(a: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
            if a is None:
                return None
            if a.ndim == 1:
                return np.interp(tq, self.t, a)
            return np.column_stack([np.interp(tq, self.t, a[:, j]) for j in range(a.shape[1])])

        q = None
        if self.q_nb is not None:
            from ..geo.frames import slerp_quat

            q = slerp_quat(self.t, self.q_nb, tq)
        return Trajectory(
            tq,
            lin(self.lla),  # type: ignore[arg-type]
            lin(self.vel_n),  # type: ignore[arg-type]
            q,
            lin(self.bias_gyro),
            lin(self.bias_accel),
            lin(self.bias_baro),
        )

    def slice(self, t0: float, t1: float) -> Trajectory:
        m = (self.t >= t0) & (self.t <= t1)

        def s(a: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
            return None if a is None else a[m]

        return Trajectory(
            self.t[m], self.lla[m], self.vel_n[m], s(self.q_nb), s(self.bias_gyro),
            s(self.bias_accel), s(self.bias_baro),
        )

    def to_rph(self) -> NDArray[np.float64]:
        """Roll, pitch, yaw [rad], shape (N, 3) (requires ``q_nb``)."""
        if self.q_nb is None:
            raise ValueError("trajectory.q_nb: no attitude in this trajectory")
        from ..geo.frames import quat_to_rph

        return quat_to_rph(self.q_nb)
