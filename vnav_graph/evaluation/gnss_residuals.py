"""The GNSS residual autocorrelation, re-exported from ``sensors.gnss_residuals`` (its home:
the estimators use it to decide on the Gauss-Markov GNSS error state, ``gnss_gm_auto``)."""

from ..sensors.gnss_residuals import (  # noqa: F401
    MIN_PAIRS,
    RESIDUAL_LAG_S,
    autocorr_at,
    gnss_residual_autocorr,
    gnss_residuals,
)
