"""The trajectory map of a run: north/east [m] from the drive's origin, seen from above.

Drawn: the truth (black, thick) where there is one; the GNSS fixes (grey dots) and those inside
the windows (orange crosses: withheld by the holdout run; a simulated outage has no fixes,
and the truth is underlaid in yellow there instead); every estimate that provides
a horizontal position, in its palette colour and line style. On a real log scored by a holdout
run the estimates are those of the holdout run, so the map shows where each went while GNSS
was withheld.

The extent (``map_extent``) is set by the reference (truth, else the GNSS fixes, else the
estimates) grown by ``ALLOW`` of its size on each side: an estimate that diverges by
kilometres leaves the map instead of shrinking the road to a dot, and is named in the notes
with how far it went.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..geo.frames import lla_to_ned
from ..types import Drive, Trajectory
from ..types.streams import FloatArray
from . import canvas
from .canvas import decimate
from .palette import estimator_style
from .panels import Plot

ALLOW = 0.5  # an estimate may widen the map by this fraction of the reference size per side
MIN_SIZE_M = 50.0  # smallest reference size [m] (a vehicle standing still)
MARGIN = 0.04
WITHHELD_COLOR = "tab:orange"
OUTAGE_COLOR = "#ffd54f"


@dataclass(frozen=True)
class Extent:
    """Map limits [m] (east ``e0..e1``, north ``n0..n1``) and the tracks that leave them:
    name → the largest distance [m] of the track outside the map."""

    e0: float
    e1: float
    n0: float
    n1: float
    outside: dict[str, float]


def _box(ne: FloatArray) -> tuple[float, float, float, float]:
    ok = np.isfinite(ne).all(axis=1)
    return (float(ne[ok, 1].min()), float(ne[ok, 1].max()), float(ne[ok, 0].min()),
            float(ne[ok, 0].max()))


def map_extent(reference: FloatArray, tracks: Mapping[str, FloatArray]) -> Extent:
    """Limits of the map (module docstring). ``reference`` (K, 2) and each track (N, 2) are
    north/east [m]; NaN rows are ignored. The reference's box, of size S = max(its east
    span, its north span, ``MIN_SIZE_M``), may grow by ``ALLOW`` × S per side to show the
    tracks; a track beyond that is named with its largest distance outside the final limits.
    A ``MARGIN`` of the size is added around."""
    e0, e1, n0, n1 = _box(reference)
    size = max(e1 - e0, n1 - n0, MIN_SIZE_M)
    ce, cn = (e0 + e1) / 2, (n0 + n1) / 2
    e0, e1 = min(e0, ce - size / 2), max(e1, ce + size / 2)
    n0, n1 = min(n0, cn - size / 2), max(n1, cn + size / 2)
    grow = ALLOW * size
    lim = (e0 - grow, e1 + grow, n0 - grow, n1 + grow)
    for ne in tracks.values():
        ok = np.isfinite(ne).all(axis=1)
        if not ok.any():
            continue
        e = np.clip(ne[ok, 1], lim[0], lim[1])
        n = np.clip(ne[ok, 0], lim[2], lim[3])
        e0, e1, n0, n1 = min(e0, e.min()), max(e1, e.max()), min(n0, n.min()), max(n1, n.max())
    pad = MARGIN * size
    e0, e1, n0, n1 = e0 - pad, e1 + pad, n0 - pad, n1 + pad
    outside = {}
    for name, ne in tracks.items():
        ok = np.isfinite(ne).all(axis=1)
        if not ok.any():
            continue
        de = np.maximum(np.maximum(e0 - ne[ok, 1], ne[ok, 1] - e1), 0.0)
        dn = np.maximum(np.maximum(n0 - ne[ok, 0], ne[ok, 0] - n1), 0.0)
        far = float(np.hypot(de, dn).max())
        if far > 0.0:
            outside[name] = far
    return Extent(float(e0), float(e1), float(n0), float(n1), outside)


def in_any(t: FloatArray, windows: Sequence[tuple[float, float]]) -> np.ndarray:
    """(N,) bool: ``t`` inside any of ``windows`` [s] (closed intervals)."""
    m = np.zeros(t.size, bool)
    for a, b in windows:
        m |= (t >= a) & (t <= b)
    return m


def _ne(tr: Trajectory, origin: FloatArray) -> FloatArray:
    s = decimate(tr.t.size, 4000)
    return lla_to_ned(tr.lla[s], origin)[:, :2]


def _broken(ne: FloatArray, mask: np.ndarray) -> FloatArray:
    """``ne`` with NaN where ``mask`` is False (a line drawn only inside the windows)."""
    out = ne.copy()
    out[~mask] = np.nan
    return out


def plot_trajectory_map(drive: Drive, tracks: Mapping[str, Trajectory],
                        windows: Sequence[tuple[float, float]], withheld_label: str | None
                        ) -> Plot | None:
    """The map figure (module docstring), or None when no track and no
    reference exist. ``tracks``: name → trajectory of the estimators that provide a
    horizontal position; ``windows`` [s]: the outages (simulated) or withheld windows;
    ``withheld_label``: the legend text of the fixes inside them, or None to draw them like
    the others (a simulated drive: its fixes are the ones the estimators were given)."""
    origin = drive.origin_lla
    ne = {n: _ne(tr, origin) for n, tr in tracks.items()}
    ne = {n: v for n, v in ne.items() if np.isfinite(v).all(axis=1).any()}
    truth_ne = None if drive.truth is None else _ne(drive.truth, origin)
    g = drive.gnss
    g_ne = None if g is None or len(g) == 0 else lla_to_ned(g.lla, origin)[:, :2]
    ref = truth_ne if truth_ne is not None else g_ne
    if ref is None:
        if not ne:
            return None
        ref = np.concatenate(list(ne.values()))
    ext = map_extent(ref, ne)
    fig = canvas.figure(11.0, 8.6, left=0.08, right=0.72, bottom_in=0.6, top_in=0.6)
    ax = fig.add_subplot(1, 1, 1)
    if truth_ne is not None:
        assert drive.truth is not None
        t_tr = drive.truth.t[decimate(drive.truth.t.size, 4000)]
        if windows:
            out = _broken(truth_ne, in_any(t_tr, windows))
            ax.plot(out[:, 1], out[:, 0], color=OUTAGE_COLOR, lw=9, alpha=0.8,
                    solid_capstyle="butt", label="truth inside a GNSS outage", zorder=1)
        ax.plot(truth_ne[:, 1], truth_ne[:, 0], color="k", lw=2.2, label="truth", zorder=2)
    if g_ne is not None and g is not None:
        w = in_any(g.t, windows) if withheld_label else np.zeros(len(g.t), bool)
        ax.plot(g_ne[~w, 1], g_ne[~w, 0], ".", color="0.55", ms=2.5, label="GNSS fix",
                zorder=3)
        if w.any():
            ax.plot(g_ne[w, 1], g_ne[w, 0], "x", color=WITHHELD_COLOR, ms=4, mew=1.0,
                    label=withheld_label, zorder=3)
    for name, v in ne.items():
        ax.plot(v[:, 1], v[:, 0], lw=1.1, label=name + (
            f" (leaves the map by {ext.outside[name]:.0f} m)" if name in ext.outside else ""),
            zorder=4, **estimator_style(name))
    if ref is not None and np.isfinite(ref).all(axis=1).any():
        k = int(np.argmax(np.isfinite(ref).all(axis=1)))
        ax.plot(ref[k, 1], ref[k, 0], "o", mfc="white", mec="k", ms=7, label="start", zorder=5)
    ax.set_xlim(ext.e0, ext.e1)
    ax.set_ylim(ext.n0, ext.n1)
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, lw=0.4, color="0.85")
    ax.set_xlabel("east of the origin [m]", fontsize=9)
    ax.set_ylabel("north of the origin [m]", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    fig.suptitle(f"Trajectory map — {drive.name} (north up, equal scale)", fontsize=10)
    notes = tuple(f"{n} leaves the map by up to {d:.0f} m" for n, d in ext.outside.items())
    return Plot(canvas.png(fig), notes)
