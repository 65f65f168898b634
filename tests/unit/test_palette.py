"""The report's palette: within a family (one panel of the overlay figures) no two estimators
share a colour or a line style, and no two core estimators share both."""

from __future__ import annotations

from itertools import combinations

from vnav_graph.estimators.base import FAMILIES
from vnav_graph.report.palette import (
    CORE_STYLES,
    DASHES,
    estimator_color,
    estimator_style,
)


def test_family_members_differ_in_colour_and_dash():
    for family, _, members in FAMILIES:
        for a, b in combinations(members, 2):
            assert estimator_color(a) != estimator_color(b), (family, a, b)
            assert estimator_style(a)["ls"] != estimator_style(b)["ls"], (family, a, b)


def test_core_pairs_unique_and_every_core_estimator_styled():
    core = [n for _, _, members in FAMILIES for n in members]
    assert set(core) == set(CORE_STYLES)
    pairs = [(estimator_color(n), estimator_style(n)["ls"]) for n in core]
    assert len(set(pairs)) == len(pairs)
    assert len({estimator_color(n) for n in core}) == len(core)  # colours alone are distinct


def test_extension_style_is_stable_and_valid():
    s = estimator_style("my-filter")
    assert s == estimator_style("my-filter")
    assert s["ls"] in DASHES.values() and s["color"].startswith("#")
    assert estimator_style("truth") == {"color": "#000000", "ls": "-"}
