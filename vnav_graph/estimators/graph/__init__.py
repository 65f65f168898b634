"""GTSAM factor-graph smoothers: ``graph-batch`` (full batch) and ``graph-isam2`` (incremental).

Public surface: ``GraphConfig``, ``GraphBatch``, ``GraphISAM2`` and ``check_jacobians`` (a
factor's Jacobians against central differences), imported on first use so that importing a
submodule does not load the estimators. Four rooms:

- ``model/``: the model. ``problem`` (set-up: keyframes, GNSS pre-gate, baro priors, IMU gaps,
  accelerometer scale factors, preintegration, interval rows at a linearisation point),
  ``cpp_factors`` (priors, keyframe fixes, IMU factor and the biases' Gauss-Markov link,
  Gauss-Markov chains, IMU-gap factors, the batch's C++ graph), ``interval_factors`` (the
  custom baro/GNSS factors between keyframes, linearised in vectorised numpy, with
  ``interp``), ``initial_guess``, ``robust``, ``builtin_sensors`` (the magnetometer) and
  ``extend`` (the public extension point: ``GraphBatch(config, extensions=[...])``, guide in
  ``docs/extending.md``);
- ``solver/``: what both estimators share. ``solve`` (Gauss-Newton / Levenberg-Marquardt,
  post-solve GNSS gate), ``layout`` + ``linalg`` (the banded-arrow fast path and selected
  inversion), ``general`` (GTSAM elimination of the linearised graph), ``outputs`` (the
  estimate of a solved graph);
- ``batch/``: ``GraphBatch``;
- ``isam2/``: the incremental front end. ``smoother`` (``GraphISAM2``), ``setup``, ``online``
  (one update per keyframe; ``states``, ``online_gate``, ``answers``), ``linear_factors`` +
  ``relin`` + ``lin_points`` (its interval factors and their relinearisation),
  ``py_factors``, ``window``, ``causal``, ``final_rounds``, ``final_check``.

Design, measurements and references in ``docs/graph.md``.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["GraphBatch", "GraphConfig", "GraphISAM2", "check_jacobians"]
_HOME = {"GraphConfig": ".settings", "GraphBatch": ".batch.smoother",
         "GraphISAM2": ".isam2.smoother", "check_jacobians": ".model.jacobians"}


def __getattr__(name: str) -> Any:
    if name in _HOME:
        return getattr(importlib.import_module(_HOME[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
