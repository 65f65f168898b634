"""``evaluation.holdout.held_forward``: a real-time answer read between its own epochs from
the latest one at or before, carried on at its velocity, never from a later epoch."""

from __future__ import annotations

import numpy as np

from vnav_graph.evaluation.holdout import held_forward
from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.types import Trajectory

ORIGIN = np.array([np.radians(47.0), np.radians(11.0), 500.0])


def _track(t: np.ndarray, v_ned: np.ndarray) -> Trajectory:
    """Constant velocity ``v_ned`` [m/s] from the origin."""
    ned = t[:, None] * v_ned
    return Trajectory(t, ned_to_lla(ned, ORIGIN), np.tile(v_ned, (t.size, 1)))


def test_constant_velocity_is_reproduced_between_epochs() -> None:
    v = np.array([12.0, -5.0, -0.8])
    tr = _track(np.arange(0.0, 20.0, 1.0), v)
    tq = np.arange(0.05, 19.0, 0.1)
    got = lla_to_ned(held_forward(tr, tq, ORIGIN).lla, ORIGIN)
    np.testing.assert_allclose(got, tq[:, None] * v, atol=1e-6)


def test_nothing_after_the_read_epoch_matters() -> None:
    """Epochs after a read time may hold anything: the value read does not change; linear
    interpolation between the epochs moves with them."""
    t = np.arange(0.0, 10.0, 1.0)
    tr = _track(t, np.array([10.0, 0.0, 0.0]))
    lla2 = tr.lla.copy()
    lla2[t > 4.5, 2] += 100.0  # a jump the answer makes at 5 s
    tr2 = Trajectory(t, lla2, tr.vel_n)
    tq = np.array([4.2, 4.9])
    a, b = held_forward(tr, tq, ORIGIN), held_forward(tr2, tq, ORIGIN)
    np.testing.assert_array_equal(a.lla, b.lla)
    assert abs(np.interp(4.9, t, lla2[:, 2]) - np.interp(4.9, t, tr.lla[:, 2])) > 80.0


def test_a_vertical_only_answer_moves_its_height_alone() -> None:
    t = np.arange(0.0, 5.0, 1.0)
    lla = np.column_stack([np.full(t.size, np.nan), np.full(t.size, np.nan), 100.0 + 2.0 * t])
    vel = np.column_stack([np.full(t.size, np.nan), np.full(t.size, np.nan),
                           np.full(t.size, -2.0)])
    got = held_forward(Trajectory(t, lla, vel), np.array([0.5, 3.25]), ORIGIN)
    np.testing.assert_allclose(got.lla[:, 2], [101.0, 106.5])
    assert np.all(np.isnan(got.lla[:, :2]))
