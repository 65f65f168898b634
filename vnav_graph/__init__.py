"""vnav_graph — INS / GNSS / barometric-altimeter navigation.

A GTSAM factor-graph smoother (iSAM2 and batch), a reference error-state EKF (+ RTS) and the
classical baro-inertial loops and vertical filters of the seed papers, all on one set of
sensor models, compared on equal terms.

Conventions
-----------
- One clock, seconds. SI units, radians; non-SI only at I/O boundaries with a suffix
  (``_deg``, ``_hpa``).
- Frames: ``n`` local-level NED (tangent-plane NED at ``Drive.origin_lla`` for ``pos_n``),
  ``b`` body/IMU forward-right-down, ``e`` ECEF. Suffix = frame of resolution (``vel_n``,
  ``gyro_b``). ``q_nb`` (w, x, y, z) maps b into n.
- ``alt`` is ellipsoidal height, +up; ``down`` is +down.
- Barometer model (``vnav_graph.sensors.baro``):
  h_b − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v, b first-order Gauss-Markov,
  h0 = drive-origin height.
"""

from .simulation import simulate
from .types import (
    ERROR_STATE,
    BaroStream,
    Drive,
    Estimate,
    GnssStream,
    ImuStream,
    Trajectory,
)

__version__ = "0.1.0"
__all__ = [
    "ERROR_STATE", "BaroStream", "Drive", "Estimate", "GnssStream", "ImuStream", "Trajectory",
    "simulate", "__version__",
]
