"""GTSAM factor-graph smoothers: ``graph-batch`` (full batch) and ``graph-isam2`` (incremental).

Public surface: ``GraphConfig``, ``GraphBatch``, ``GraphISAM2`` and ``check_jacobians`` (a
factor's Jacobians against central differences), imported on first use so that importing a
submodule does not load the estimators. Three rooms:

- ``model/``: the model. ``problem`` (set-up: keyframes, GNSS pre-gate, baro priors, IMU gaps,
  accelerometer scale factors, preintegration, interval rows at a linearisation point),
  ``cpp_factors`` (priors, keyframe fixes, IMU factor and the biases' Gauss-Markov link,
  Gauss-Markov chains, IMU-gap factors, the batch's C++ graph), ``interval_factors`` (the
  custom baro/GNSS factors between keyframes, linearised in vectorised numpy, with
  ``interp``), ``initial_guess``, ``robust``, ``magnetometer`` and ``extend`` (the public
  extension point: ``GraphBatch(config, extensions=[...])``, guide in
  ``docs/extending.md``);
- ``batch/``: the batch solver. ``solve`` (Gauss-Newton / Levenberg-Marquardt, post-solve GNSS
  gate), ``layout`` + ``linalg`` (the banded-arrow fast path and selected inversion),
  ``general`` (GTSAM elimination of the linearised graph), ``smoother`` (outputs,
  ``GraphBatch``);
- ``isam2/``: the incremental front end. ``smoother`` (``GraphISAM2``), ``setup``, ``online``
  (one update per keyframe), ``linear_factors`` + ``relin`` (its interval factors and their
  relinearisation), ``window``.

Design, measurements and references in ``docs/graph.md``.
"""

from __future__ import annotations

from typing import Any

__all__ = ["GraphBatch", "GraphConfig", "GraphISAM2", "check_jacobians"]


def __getattr__(name: str) -> Any:
    if name == "GraphConfig":
        from .settings import GraphConfig

        return GraphConfig
    if name == "GraphBatch":
        from .batch.smoother import GraphBatch

        return GraphBatch
    if name == "GraphISAM2":
        from .isam2.smoother import GraphISAM2

        return GraphISAM2
    if name == "check_jacobians":
        from .model.jacobians import check_jacobians

        return check_jacobians
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
