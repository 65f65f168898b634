"""The batch solver of ``graph-batch``: Gauss-Newton / Levenberg-Marquardt over the
banded-arrow (``layout``, ``linalg``) or the general sparse (``general``) linear algebra, and
the outputs shared with ``graph-isam2`` (``smoother``)."""
