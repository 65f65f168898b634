"""GNSS-height fault detection and exclusion: one probation gate for every filter.

A fix's height is *usable* when its reported σ_v ≤ the estimator's limit; it *passes* when
also ν² ≤ γ·S (ν the innovation, S its variance, γ the χ²₁ threshold). Rule:

- while the GNSS height is trusted, a fix that passes is used; a refusal is only a refusal;
- after two consecutive refusals the GNSS height is *on probation* (a persistent fault such
  as multipath or a bad geoid switch): it is used again only once fixes have passed for
  ``probation_s`` seconds without a break;
- after ``max_consec`` consecutive refusals (a long run: the filter, not the receiver, may
  be wrong) the probation test is widened by ``widen_var`` (the baro-bias prior variance:
  "nothing has been learned about the bias"), and the fix that completes probation is
  reported with ``USE_INFLATE`` so the caller re-opens that prior; without a barometer
  (``force``) a long run ends by accepting the fix.

Pass ``max_consec`` ≥ 2**62 and ``widen_var`` = 0 for the plain rule (vekf7, vkf4). The gate
state is a float64 array of 3 (``new_gate_state``) so numba kernels and Python loops share
the one implementation (:func:`height_gate` is compiled and callable from both).
"""

from __future__ import annotations

import numpy as np
from numba import njit

REFUSE = 0
USE = 1
USE_INFLATE = 2
NO_LIMIT = 2**62


def new_gate_state() -> np.ndarray:
    """Fresh gate state: [consecutive refusals, on probation (0/1), probation run start]."""
    return np.array([0.0, 0.0, np.nan])


@njit(cache=True)
def height_gate(state, t, usable, nu2, s, gate, probation_s, max_consec, widen_var, force):
    """Decide on one GNSS height (module docstring); updates ``state`` in place.

    t [s] fix time, usable: σ_v within the limit, nu2 = ν² [m²], s = S [m²], gate: χ²
    threshold γ, probation_s [s], max_consec, widen_var [m²], force: accept at the end of a
    long run (no barometer). Returns REFUSE, USE or USE_INFLATE."""
    consec = state[0]
    suspect = state[1] > 0.5
    long_run = consec >= max_consec
    code = REFUSE
    if long_run and force:
        code = USE
    elif not suspect:
        if usable and nu2 <= gate * s:
            code = USE
    else:
        s_t = s + (widen_var if long_run else 0.0)
        if usable and nu2 <= gate * s_t:
            if np.isnan(state[2]):
                state[2] = t
            if t - state[2] >= probation_s:
                code = USE_INFLATE if long_run else USE
        else:
            state[2] = np.nan
    if code != REFUSE:
        state[0] = 0.0
        state[1] = 0.0
        state[2] = np.nan
    else:
        state[0] = consec + 1.0
        if not suspect and state[0] >= 2.0:
            state[1] = 1.0
            state[2] = np.nan
    return code
