"""One configuration per comparison: every option the filter family (``EkfConfig``) and the
graph family (``GraphConfig``) share has one default, listed here with the pairs that go by
two names; everything else is family-specific and named in docs/design.md ("Options of one
family only")."""

from __future__ import annotations

import dataclasses

from vnav_graph.estimators.ekf.settings import EkfConfig
from vnav_graph.estimators.graph.settings import GraphConfig

# the same quantity under one name in both
SHARED = ("accel_scale", "baro_scale_sd", "gnss_gm_auto", "gnss_gm_sd_h", "gnss_gm_sd_v",
          "gnss_gm_tau_s", "loss_baro", "loss_gnss_pos", "loss_gnss_vel", "loss_threshold_sd",
          "mag_bias_sd", "mag_heading_floor", "mag_interval_s", "use_mag", "zupt")
# (EkfConfig name, GraphConfig name): the same quantity under two names
PAIRS = (("post_gate_prob", "gnss_gate_prob"), ("post_gate_rounds", "gate_rounds"))


def _defaults(cls: type) -> dict[str, object]:
    return {f.name: f.default for f in dataclasses.fields(cls)}


def test_the_shared_options_are_the_fields_both_have() -> None:
    e, g = _defaults(EkfConfig), _defaults(GraphConfig)
    assert set(SHARED) == set(e) & set(g)


def test_each_shared_option_is_declared_once() -> None:
    """Both configs take the shared options from one block (``SharedSettings``): neither
    declares one of them again."""
    from vnav_graph.estimators.shared_settings import SharedSettings

    assert set(SHARED) == {f.name for f in dataclasses.fields(SharedSettings)}
    for cls in (EkfConfig, GraphConfig):
        assert issubclass(cls, SharedSettings)
        own = set(getattr(cls, "__annotations__", {}))
        assert not own & set(SHARED), (cls.__name__, sorted(own & set(SHARED)))


def test_shared_options_have_equal_defaults() -> None:
    e, g = _defaults(EkfConfig), _defaults(GraphConfig)
    differ = {k: (e[k], g[k]) for k in SHARED if e[k] != g[k]}
    differ |= {f"{a}/{b}": (e[a], g[b]) for a, b in PAIRS if e[a] != g[b]}
    assert not differ, differ


def test_both_families_gate_fixes_after_the_solve_by_default() -> None:
    """The graphs always run their post-solve gate (``gate_rounds``); ekf-rts's counterpart
    (``post_gate``) is on by default too, so a default comparison is one configuration."""
    assert EkfConfig().post_gate is True
    assert GraphConfig().gate_rounds > 0 and GraphConfig().gnss_gate_prob > 0
