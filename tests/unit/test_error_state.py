"""``nav.error_state``: an estimator's covariance mapped into the ERROR_STATE layout."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.nav.error_state import (
    BARO_COMPONENTS,
    component,
    embed_error_state,
    mark_absent,
    selection,
)
from vnav_graph.types import ERROR_STATE_DIM


def test_component_rows_and_bad_axis():
    assert component("pos_n", 2) == 2
    assert component("vel_n", 2) == 5
    assert component("baro_bias") == 17
    with pytest.raises(ValueError, match="baro_scale has 1 axes"):
        component("baro_scale", 1)


def test_embed_is_t_p_t_with_nan_where_unreached():
    # a 2-state filter: height (estimated − true with the opposite sign) and baro bias
    p = np.array([[4.0, 1.0], [1.0, 9.0]])
    t = selection((("pos_n", 2, 0, -1.0), ("baro_bias", 0, 1, 1.0)), 2)
    out = embed_error_state(p, t)
    assert out.shape == (ERROR_STATE_DIM, ERROR_STATE_DIM)
    assert out[2, 2] == 4.0 and out[17, 17] == 9.0
    assert out[2, 17] == out[17, 2] == -1.0  # the sign flips the cross term only
    reached = np.zeros(ERROR_STATE_DIM, dtype=bool)
    reached[[2, 17]] = True
    assert np.isnan(out[~reached]).all() and np.isnan(out[:, ~reached]).all()
    # a stack gives the same as one at a time
    stack = embed_error_state(np.stack([p, 2 * p]), t)
    np.testing.assert_array_equal(stack[0], out)
    np.testing.assert_array_equal(stack[1][reached][:, reached], 2 * out[reached][:, reached])


def test_mark_absent_blanks_the_baro_block():
    cov = np.eye(ERROR_STATE_DIM)
    mark_absent(cov, BARO_COMPONENTS)
    assert np.isnan(cov[15:18]).all() and np.isnan(cov[:, 15:18]).all()
    assert cov[14, 14] == 1.0
