"""GTSAM factor-graph smoothers: ``graph-batch`` (full batch) and ``graph-isam2`` (incremental).

Public surface: ``GraphConfig``, ``GraphBatch``, ``GraphISAM2`` (imported on first use, so that
importing a submodule such as ``factors`` does not load the estimators). Modules:

- ``problem``: problem set-up (GNSS pre-gate, baro priors, IMU gaps, accelerometer scale
  factors), preintegration and the interval rows of the custom baro/GNSS terms at a
  linearisation point;
- ``builders``: the C++ factors (priors, keyframe fixes, IMU factor and the biases'
  Gauss-Markov link, Gauss-Markov chains, IMU-gap factors, the batch's C++ graph);
- ``factors``: the custom baro/GNSS terms, linearised in vectorised numpy, and frame helpers;
- ``init``: initial keyframe states from GNSS and the IMU;
- ``solve``: batch Gauss-Newton / Levenberg-Marquardt with the post-solve GNSS gate;
- ``layout``: column layout from the graph's keys, the banded-arrow fast path (system and
  covariance) and the test whether a graph fits it;
- ``linalg``: banded-arrow normal equations, Cholesky and selected inversion;
- ``general``: the general sparse path (GTSAM elimination of the linearised graph) and the
  interval information blocks as GTSAM HessianFactor pieces;
- ``batch``: outputs (trajectory, covariance, baro parameters) and ``GraphBatch``;
- ``isam2``: ``GraphISAM2``, the incremental front end;
- ``extend``: the public extension point — user factors and variables for both smoothers
  (``GraphBatch(config, extensions=[...])``, ``GraphISAM2(config, extensions=[...])``;
  guide in ``docs/extending.md``).

Design, measurements and references in ``docs/graph.md``.
"""

from __future__ import annotations

from typing import Any

__all__ = ["GraphBatch", "GraphConfig", "GraphISAM2"]


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
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
