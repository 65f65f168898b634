"""The solver both graph estimators share: Gauss-Newton / Levenberg-Marquardt over the
banded-arrow (``layout``, ``linalg``) or the general sparse (``general``) linear algebra, and
the estimate of a solved graph (``outputs``)."""
