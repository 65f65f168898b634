"""The shell every vertical estimator shares: its configuration, a timed ``run`` that first
checks the streams it needs, and its answer as a vertical-only ``Estimate`` (north and east
NaN; height [m] and down velocity [m/s] at the IMU epochs)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from ...types import Drive, Estimate, Trajectory
from ...types.streams import FloatArray
from ...util.failures import MissingStream


def vertical_estimate(name: str, t: FloatArray, h: FloatArray, v_down: FloatArray,
                      config: Any, provides: frozenset[str] = frozenset({"alt", "vel_d"}),
                      **fields: Any) -> Estimate:
    """An ``Estimate`` whose trajectory is height ``h`` and down velocity ``v_down`` at ``t``
    (north and east NaN); ``fields``: the other ``Estimate`` fields (cov, baro, info, ...)."""
    nan = np.full(t.size, np.nan)
    traj = Trajectory(t, np.column_stack([nan, nan, h]), np.column_stack([nan, nan, v_down]))
    return Estimate(estimator=name, trajectory=traj, provides=provides, config=config,
                    **fields)


class VerticalEstimator:
    """``name``, ``config_class`` (its default settings), ``needs_baro``; subclasses write
    ``solve(drive)``, and ``run`` times it (``Estimate.runtime_s``) after the stream check."""

    name: ClassVar[str]
    config_class: ClassVar[type]
    needs_baro: ClassVar[bool] = False

    def __init__(self, config: Any = None) -> None:
        self.config = self.config_class() if config is None else config

    def solve(self, drive: Drive) -> Estimate:
        raise NotImplementedError

    def run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        if self.needs_baro and drive.baro is None:
            raise MissingStream("barometer", f"{self.name}: the drive has no barometer stream")
        est = self.solve(drive)
        return replace(est, runtime_s=time.perf_counter() - t0)
