"""PNG plots of the barometer parameters of a run: final values ± 1σ, and their histories.

(The error plots are in :mod:`vnav_graph.report.error_plots`.) Matplotlib is used through
the object-oriented API with the Agg canvas (:mod:`vnav_graph.report.canvas`), never pyplot's
global backend, so it works without a display.

Each ``plot_*`` function returns the PNG bytes of one figure, or None when nothing applies.
Long series are decimated to at most ``canvas.MAX_POINTS`` samples per line (a 1-hour drive at
200 Hz would otherwise draw 720 000 points per estimator). Shaded spans are the GNSS outage
windows of a simulated drive, or the withheld windows of a real log's holdout run.

Baro parameter histories: an estimator may put ``info["baro_history"]``, a mapping with
``"t"`` (M,) [s] and any of ``"scale"``, ``"scale_sd"`` [-], ``"latency_s"``, ``"latency_sd"``
[s], ``"bias_m"``, ``"bias_sd"`` [m], each (M,). The bias history also comes from
``Trajectory.bias_baro`` with σ from ``cov[:, 17, 17]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate
from ..types.streams import FloatArray
from . import canvas
from .canvas import decimate
from .palette import estimator_style


def _plain_log_ticks(ax: Any) -> None:
    """Log axis labelled 1, 2, 5 × 10ⁿ in plain numbers ("0.02", "5"), minor ticks unlabelled:
    a range under a decade otherwise gets minor labels like "1.975×10⁰" that crowd the axis
    and push its label off the figure."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())

_IDX = {"scale": ERROR_STATE["baro_scale"].start, "latency_s": ERROR_STATE["baro_latency"].start,
        "bias_m": ERROR_STATE["baro_bias"].start}
# (key, label, display scale) of the three baro parameters
BARO_PARAMS = (("scale", "scale error s [%]", 100.0), ("latency_s", "latency τd [ms]", 1000.0),
               ("bias_m", "bias b [m]", 1.0))


def _shade(ax: Any, windows: Sequence[tuple[float, float]]) -> None:
    for a, b in windows:
        ax.axvspan(a, b, color=canvas.SHADE, zorder=0)


def _ok(results: Sequence[Any]) -> list[Estimate]:
    return [r.estimate for r in results if r.estimate is not None]


def _final_param(est: Estimate, key: str) -> tuple[float, float | None] | None:
    if est.baro is None:
        return None
    p = getattr(est.baro, key)
    return None if p is None else (float(p.est), None if p.sd is None else float(p.sd))


def baro_truth(drive: Drive) -> dict[str, float | None]:
    """True scale [-], latency [s] and time-mean bias [m] of a simulated drive (else None)."""
    bt = drive.baro_truth
    bias = None
    if drive.truth is not None and drive.truth.bias_baro is not None:
        bias = float(np.mean(drive.truth.bias_baro))
    return {"scale": None if bt is None else float(bt.scale),
            "latency_s": None if bt is None else float(bt.latency_s), "bias_m": bias}


def plot_baro_parameters(drive: Drive, results: Sequence[Any]) -> bytes | None:
    """Final baro parameter estimates ± 1σ per estimator (error bars) beside the truth."""
    ests = [e for e in _ok(results) if e.baro is not None]
    if not ests:
        return None
    truth = baro_truth(drive)
    fig = canvas.figure(11.0, 3.2, left=0.1, wspace=0.45)
    axes = fig.subplots(1, 3)
    for ax, (key, label, sc) in zip(axes, BARO_PARAMS, strict=True):
        names, vals, sds = [], [], []
        for est in ests:
            p = _final_param(est, key)
            if p is not None:
                names.append(est.estimator)
                vals.append(p[0] * sc)
                sds.append(np.nan if p[1] is None else p[1] * sc)
        y = np.arange(len(names))
        if names:
            ax.errorbar(vals, y, xerr=np.nan_to_num(np.array(sds)), fmt="o", ms=4, capsize=3)
            ax.set_yticks(y, names, fontsize=8)
            ax.set_ylim(-0.6, len(names) - 0.4)
        else:
            ax.set_yticks([])
            ax.text(0.5, 0.5, "not estimated", ha="center", va="center", transform=ax.transAxes)
        if truth[key] is not None:
            ax.axvline(truth[key] * sc, color="k", ls="--", lw=1, label="truth")
            ax.legend(fontsize=7)
        ax.set_xlabel(label, fontsize=9)
        ax.tick_params(labelsize=8)
    fig.suptitle("Baro parameters: estimate ± 1σ" + (" vs truth (bias: time mean of b(t))"
                                                     if truth["scale"] is not None else ""),
                 fontsize=10)
    return canvas.png(fig)


def baro_histories(est: Estimate) -> dict[str, tuple[FloatArray, FloatArray,
                                                     FloatArray | None]]:
    """Time histories (t, value, σ or None) of the baro parameters an estimate provides."""
    out: dict[str, tuple[FloatArray, FloatArray, FloatArray | None]] = {}
    hist = est.info.get("baro_history")
    if hist is not None and "t" in hist:
        t = np.asarray(hist["t"], dtype=float)
        for key, sd_key in (("scale", "scale_sd"), ("latency_s", "latency_sd"),
                            ("bias_m", "bias_sd")):
            if key in hist and hist[key] is not None:
                sd = hist.get(sd_key)
                out[key] = (t, np.asarray(hist[key], dtype=float),
                            None if sd is None else np.asarray(sd, dtype=float))
    tr = est.trajectory
    if "bias_m" not in out and tr.bias_baro is not None and np.all(np.isfinite(tr.bias_baro)):
        sd = None
        if est.cov is not None and est.t_cov is not None:
            v = est.cov[:, _IDX["bias_m"], _IDX["bias_m"]]
            ok = np.isfinite(v)
            if ok.any():
                sd = np.sqrt(np.clip(np.interp(tr.t, est.t_cov[ok], v[ok]), 0, None))
        out["bias_m"] = (tr.t, tr.bias_baro, sd)
    return out


def baro_sd_histories(est: Estimate) -> dict[str, tuple[FloatArray, FloatArray]]:
    """(t_cov, 1σ) of the baro scale and latency from ``Estimate.cov`` where it is finite."""
    out: dict[str, tuple[FloatArray, FloatArray]] = {}
    if est.cov is None or est.t_cov is None:
        return out
    for key in ("scale", "latency_s"):
        v = est.cov[:, _IDX[key], _IDX[key]]
        ok = np.isfinite(v)
        if ok.sum() >= 2:
            out[key] = (est.t_cov[ok], np.sqrt(np.clip(v[ok], 0.0, None)))
    return out


def plot_baro_convergence(drive: Drive, results: Sequence[Any],
                          windows: Sequence[tuple[float, float]] = ()) -> bytes | None:
    """Baro parameter estimates vs time (±1σ where known) with the truth, and the σ of the
    scale and latency from the covariance (log scale: how fast the data make them
    observable). ``windows`` [s] are shaded. None when no estimator provides any of these."""
    ests = _ok(results)
    hists = {e.estimator: h for e in ests if (h := baro_histories(e))}
    sds = {e.estimator: h for e in ests if (h := baro_sd_histories(e))}
    if not hists and not sds:
        return None
    panels = [("value", k) for k, _, _ in BARO_PARAMS if any(k in h for h in hists.values())]
    panels += [("sd", k) for k in ("scale", "latency_s") if any(k in h for h in sds.values())]
    fig = canvas.figure(11.0, 0.6 + 2.1 * len(panels), right=0.84)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False).ravel()
    truth = baro_truth(drive)
    for ax, (kind, key) in zip(axes, panels, strict=True):
        label, sc = next((lb, s) for k, lb, s in BARO_PARAMS if k == key)
        _shade(ax, windows)
        if kind == "sd":
            for name, h in sds.items():
                if key in h:
                    t, sd = h[key]
                    s = decimate(t.size)
                    ax.plot(t[s], sd[s] * sc, lw=0.9, label=name, **estimator_style(name))
            ax.set_yscale("log")
            _plain_log_ticks(ax)
            ax.set_ylabel("σ of " + label, fontsize=8)
        else:
            for name, h in hists.items():
                if key not in h:
                    continue
                t, v, sd = h[key]
                s = decimate(t.size)
                (line,) = ax.plot(t[s], v[s] * sc, lw=0.9, label=name,
                                  **estimator_style(name))
                if sd is not None:
                    ax.fill_between(t[s], (v[s] - sd[s]) * sc, (v[s] + sd[s]) * sc,
                                    color=line.get_color(), alpha=0.15, lw=0)
            if key == "bias_m" and drive.truth is not None and drive.truth.bias_baro is not None:
                s = decimate(drive.truth.t.size)
                ax.plot(drive.truth.t[s], drive.truth.bias_baro[s], "k--", lw=1, label="truth")
            elif truth[key] is not None:
                ax.axhline(truth[key] * sc, color="k", ls="--", lw=1, label="truth")
            ax.set_ylabel(label, fontsize=8)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
        ax.tick_params(labelsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Baro parameter convergence (band: ±1σ; σ panels from the covariance)",
                 fontsize=10)
    return canvas.png(fig)


def plot_fb_separation(results: Sequence[Any],
                       windows: Sequence[tuple[float, float]] = ()) -> bytes | None:
    """Forward/backward separation over time (``info["fb_separation"]["series"]``, from
    ``ekf-rts``): altitude and horizontal, with their 95th percentiles dashed."""
    ests = [e for e in _ok(results) if (e.info or {}).get("fb_separation")]
    if not ests:
        return None
    fig = canvas.figure(11.0, 4.2, left=0.08, right=0.80)
    axes = fig.subplots(2, 1, sharex=True)
    for est in ests:
        sep = est.info["fb_separation"]
        ser = sep["series"]
        t = np.asarray(ser["t"], dtype=float)
        for ax, key, p95 in ((axes[0], "alt_m", sep["alt_p95_m"]),
                             (axes[1], "horiz_m", sep["horiz_p95_m"])):
            k = decimate(t.size)
            tt, y = t[k], np.asarray(ser[key], dtype=float)[k]
            style = estimator_style(est.estimator)
            ax.plot(tt, y, lw=0.8, label=f"{est.estimator} (p95 {p95:.2f} m)", **style)
            ax.axhline(p95, color=style["color"], ls="--", lw=0.8)
    for ax, label in zip(axes, ("altitude [m]", "horizontal [m]"), strict=True):
        _shade(ax, windows)
        ax.set_ylabel(label, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    axes[1].set_xlabel("time [s]", fontsize=9)
    fig.suptitle("Forward/backward filter separation", fontsize=10)
    return canvas.png(fig)
