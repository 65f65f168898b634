"""Validation shared by every data type of ``vnav_graph.types``: read-only arrays, time
stamps, shapes, finite values and plausible latitude, longitude and height."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

ALT_RANGE = (-1000.0, 60000.0)  # m: a height outside is a unit or datum mistake


def as_array(x: Any, dtype: Any = np.float64) -> NDArray[np.float64]:
    # an array that is already read-only, of this dtype and owns its memory (another record's
    # field, e.g. a drive rebuilt with ``Drive.replace``) cannot change: shared, not copied
    # (the copies doubled the truth arrays while a simulated drive was assembled)
    if (isinstance(x, np.ndarray) and x.dtype == dtype and x.base is None
            and not x.flags.writeable and x.flags.c_contiguous):
        return x
    a = np.array(x, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


def check_time(name: str, t: NDArray[np.float64]) -> None:
    if t.ndim != 1:
        raise ValueError(f"{name}.t: expected shape (N,), got {t.shape}")
    if t.size == 0:
        raise ValueError(f"{name}.t: stream is empty")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}.t: contains NaN or inf")
    d = np.diff(t)
    if np.any(d == 0):
        i = int(np.flatnonzero(d == 0)[0])
        raise ValueError(f"{name}.t: duplicated time stamp {t[i]!r} at index {i + 1}")
    if np.any(d < 0):
        i = int(np.flatnonzero(d < 0)[0])
        raise ValueError(f"{name}.t: not monotonic (t[{i + 1}] = {t[i + 1]!r} < {t[i]!r})")


def check_shape(name: str, a: NDArray[np.float64] | None, shape: tuple[int, ...]) -> None:
    if a is None:
        return
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")


def check_finite(name: str, a: NDArray[np.float64] | None) -> None:
    if a is not None and not np.all(np.isfinite(a)):
        n_bad = int(np.sum(~np.isfinite(a)))
        raise ValueError(f"{name}: contains {n_bad} NaN or inf value(s)")


def check_lla(name: str, lla: NDArray[np.float64]) -> None:
    if np.any(np.abs(lla[:, 0]) > np.pi / 2 + 1e-12) or np.any(np.abs(lla[:, 1]) > 2 * np.pi):
        raise ValueError(
            f"{name}: latitude/longitude out of range for radians (degrees passed as radians?)"
        )
    lo, hi = ALT_RANGE
    if np.any(lla[:, 2] < lo) or np.any(lla[:, 2] > hi):
        raise ValueError(f"{name}: height outside [{lo:g}, {hi:g}] m")
