"""Shared navigation numerics used by every estimator family (docs/design.md, target layout).

``rotations``: SO(3) and quaternion kernels (numba) — cross/skew, quaternion product and
exponential, rotation matrices, roll-pitch-yaw ↔ quaternion; ``levelling``: roll and pitch
from a static specific force. Whole trajectories are converted by ``vnav_graph.geo.frames``
with scipy's ``Rotation``; tests check that both agree.
"""
