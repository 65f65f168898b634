"""Shared navigation numerics used by every estimator family (docs/design.md, target layout).

``rotations``: SO(3) and quaternion kernels (numba) — cross/skew, quaternion product and
exponential, rotation matrices, roll-pitch-yaw ↔ quaternion; ``levelling``: roll and pitch
from a static specific force. Vectorised numpy twins for whole trajectories live in
``vnav_graph.geo.frames`` and are tested equal to these kernels.
"""
