"""How estimators share a panel and a y-scale: families, and robust limits with clipping notes.

Estimators are drawn in three families (docs/design.md names): smoothers, filters, and
loops/observers; any other name (a user's estimator) goes to "other". Within a family the
y-scale is shared, so the members are compared at a glance.

Robust limits: per member, ``q99 = 99th percentile of |error|``. A member is an outlier when
its ``q99`` exceeds ``OUTLIER_FACTOR`` × the lower median of the members' ``q99`` (the lower
median, so that with two members the larger one can be the outlier). The robust limit ``L``
is ``MARGIN`` × the largest ``q99`` of the other members. A member whose ``max |error|`` is
within ``SPIKE_FACTOR`` × ``L`` is shown whole (the limit grows to fit it); every member
beyond the final limit is clipped and named in a note, e.g. "observer1d clipped: max |err|
440 m". So a rare large spike, or an estimator far worse than its family, is clipped rather
than setting the scale, and a modest excursion is not clipped at all.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..estimators.base import FAMILIES, OTHER_FAMILY, family_order
from ..types.streams import FloatArray

GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = tuple((f, m) for f, _, m in FAMILIES)
OTHER = OTHER_FAMILY[0]
PERCENTILE = 99.0
OUTLIER_FACTOR = 5.0
MARGIN = 1.15
SPIKE_FACTOR = 2.0


def group_names(names: Iterable[str]) -> list[tuple[str, list[str]]]:
    """``[(family, [members in family order]), ...]`` for the families that have a member."""
    names = list(names)
    out = []
    known = set()
    for label, members in GROUPS:
        have = [n for n in members if n in names]
        known.update(members)
        if have:
            out.append((label, have))
    rest = [n for n in names if n not in known]
    if rest:
        out.append((OTHER, rest))
    return out


@dataclass(frozen=True)
class Limits:
    """Symmetric y-limit ``±lim`` and the members clipped by it (name → max |error|)."""

    lim: float
    clipped: dict[str, float]

    def notes(self, unit: str) -> list[str]:
        return [f"{n} clipped: max |err| {_g(v)} {unit}" for n, v in self.clipped.items()]


def _g(v: float) -> str:
    return f"{v:.3g}" if v < 100 else f"{v:.0f}"


def robust_limits(errors: Mapping[str, FloatArray | None], floor: float = 1e-3) -> Limits:
    """Shared symmetric limit of a family's error series (module docstring).

    ``errors``: name → error samples (NaN ignored). ``floor``: smallest limit returned.
    """
    absval = {n: np.abs(e[np.isfinite(e)]) for n, e in errors.items() if e is not None}
    absval = {n: a for n, a in absval.items() if a.size}
    if not absval:
        return Limits(1.0, {})
    q = {n: float(np.percentile(a, PERCENTILE)) for n, a in absval.items()}
    ref = float(np.sort(list(q.values()))[(len(q) - 1) // 2])  # lower median
    kept = [v for v in q.values() if v <= OUTLIER_FACTOR * ref] or list(q.values())
    robust = max(MARGIN * max(kept), floor)
    fits = [1.05 * float(a.max()) for a in absval.values() if a.max() <= SPIKE_FACTOR * robust]
    lim = max([robust, *fits])
    clipped = {n: float(a.max()) for n, a in absval.items() if a.max() > lim}
    return Limits(lim, clipped)


def ordered(names: Sequence[str]) -> list[str]:
    """The names in family order (smoothers, filters, loops/observers, other):
    ``estimators.base.family_order``, the terminal table's order too."""
    return family_order(list(names))
