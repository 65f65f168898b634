"""PNG plots of a run: altitude error with ±3σ bands, vertical-velocity error, baro parameters.

The only module of vnav_graph that imports matplotlib. It uses the object-oriented API with
the Agg canvas (``matplotlib.figure.Figure`` + ``FigureCanvasAgg``), so it never touches
pyplot's global backend and works without a display.

Each ``plot_*`` function returns the PNG bytes of one figure, or None when nothing applies
(e.g. no estimator provides vertical velocity). Long series are decimated to at most
``MAX_POINTS`` samples per line (plots stay fast: a 1-hour drive at 200 Hz would otherwise draw
720 000 points per estimator).

Conventions: error = estimate − reference (truth for simulated drives, GNSS fixes otherwise),
altitude +up [m], vertical velocity +down [m/s]. The ±3σ band of the altitude is
3·sqrt(P[2, 2]) of ``Estimate.cov`` (``ERROR_STATE["pos_n"]`` down component) interpolated to
the error epochs; against GNSS it is 3·sqrt(P[2, 2] + σ_GNSS,D²) (the withheld fix is
independent of the estimate). Shaded spans are the GNSS outage windows of a simulated drive
(``drive.meta["gnss_outages"]``) or the holdout windows of a real log
(``drive.meta["holdout_windows"]``).

Baro parameter histories: an estimator may put ``info["baro_history"]``, a mapping with
``"t"`` (M,) [s] and any of ``"scale"``, ``"scale_sd"`` [-], ``"latency_s"``, ``"latency_sd"``
[s], ``"bias_m"``, ``"bias_sd"`` [m], each (M,). The bias history also comes from
``Trajectory.bias_baro`` with σ from ``cov[:, 17, 17]``.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate, FloatArray

MAX_POINTS = 1500
DPI = 90
_ALT = ERROR_STATE["pos_n"].start + 2  # down position row of the error state
_IDX = {"scale": ERROR_STATE["baro_scale"].start, "latency_s": ERROR_STATE["baro_latency"].start,
        "bias_m": ERROR_STATE["baro_bias"].start}
# (key, label, display scale) of the three baro parameters
BARO_PARAMS = (("scale", "scale error s [%]", 100.0), ("latency_s", "latency τd [ms]", 1000.0),
               ("bias_m", "bias b [m]", 1.0))


def _figure(w: float, h: float, left: float = 0.08, wspace: float = 0.12) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    # fixed margins instead of constrained layout: the layout solver cost ~1 s per figure
    fig = Figure(figsize=(w, h), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left, right=0.98, bottom=0.55 / h, top=1.0 - 0.7 / h,
                        hspace=0.45, wspace=wspace)
    return fig


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def decimate(n: int, max_points: int = MAX_POINTS) -> slice:
    """Stride slice keeping at most ``max_points`` of ``n`` samples."""
    return slice(None, None, max(1, int(np.ceil(n / max_points))))


def outage_windows(drive: Drive) -> list[tuple[float, float]]:
    """GNSS outage windows (simulated) or holdout windows (real logs) clipped to the drive."""
    w = drive.meta.get("gnss_outages") if drive.source == "simulated" else None
    if w is None:
        w = drive.meta.get("holdout_windows") or drive.meta.get("gnss_outages") or []
    t0, t1 = drive.imu.t[0], drive.imu.t[-1]
    return [(max(float(a), t0), min(float(b), t1)) for a, b in w if b > t0 and a < t1]


def _shade(ax: Any, windows: Sequence[tuple[float, float]], label: bool) -> None:
    for k, (a, b) in enumerate(windows):
        ax.axvspan(a, b, color="0.85", zorder=0, label="GNSS outage" if label and k == 0 else None)


def _alt_sd(est: Estimate, t: FloatArray) -> FloatArray | None:
    if est.cov is None or est.t_cov is None:
        return None
    var = est.cov[:, _ALT, _ALT]
    ok = np.isfinite(var)
    if ok.sum() < 1:
        return None
    return np.sqrt(np.clip(np.interp(t, est.t_cov[ok], var[ok]), 0.0, None))


def altitude_errors(est: Estimate, drive: Drive) -> tuple[FloatArray, FloatArray,
                                                          FloatArray | None, str]:
    """(t, error, 1σ or None, reference name) of the altitude of ``est``.

    With truth: ĥ(t) − h(t) at the estimate epochs. Without: ĥ(t_k) − h_GNSS(t_k) at the GNSS
    fixes inside the estimate span, σ = sqrt(P_DD + σ_GNSS,D²).
    """
    tr = est.trajectory
    if drive.truth is not None:
        t, e, _ = truth_errors(est, drive)
        return t, e, _alt_sd(est, t), "truth"
    if drive.gnss is None:
        raise ValueError("no truth and no GNSS to compare with")
    g = drive.gnss
    m = (g.t >= tr.t[0]) & (g.t <= tr.t[-1])
    t = g.t[m]
    e = np.interp(t, tr.t, tr.alt) - g.lla[m, 2]
    sd = _alt_sd(est, t)
    if sd is not None:
        sd = np.sqrt(sd**2 + g.pos_sd[m, 2] ** 2)
    return t, e, sd, "GNSS"


def truth_errors(est: Estimate, drive: Drive) -> tuple[FloatArray, FloatArray,
                                                       FloatArray | None]:
    """(t, altitude error, down-velocity error or None) against truth at the estimate epochs
    inside the truth span: the quantities of ``metrics.errors_vs_truth`` (linear
    interpolation of the truth), without interpolating the attitude, which plots do not use
    and which costs a slerp of every epoch."""
    tr, truth = est.trajectory, drive.truth
    assert truth is not None
    m = (tr.t >= truth.t[0]) & (tr.t <= truth.t[-1])
    t = tr.t[m]
    alt = tr.alt[m] - np.interp(t, truth.t, truth.alt)
    vd = None
    if "vel_d" in est.provides:
        vd = tr.vel_down[m] - np.interp(t, truth.t, truth.vel_down)
    return t, alt, vd


def _ok(results: Sequence[Any]) -> list[Estimate]:
    return [r.estimate for r in results if r.estimate is not None]


def plot_altitude_errors(drive: Drive, results: Sequence[Any]) -> bytes | None:
    """One panel per estimator: altitude error vs time, ±3σ band, outages shaded."""
    ests = _ok(results)
    if not ests:
        return None
    ncol = 2 if len(ests) > 1 else 1
    nrow = int(np.ceil(len(ests) / ncol))
    fig = _figure(11.0, 0.6 + 2.0 * nrow)
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False).ravel()
    windows = outage_windows(drive)
    ref = "truth"
    for k, (ax, est) in enumerate(zip(axes, ests, strict=False)):
        t, e, sd, ref = altitude_errors(est, drive)
        s = decimate(t.size)
        _shade(ax, windows, label=k == 0)
        lim = 1.3 * float(np.max(np.abs(e))) if e.size else 1.0
        if sd is not None:
            ax.fill_between(t[s], -3 * sd[s], 3 * sd[s], color="tab:blue", alpha=0.18, lw=0,
                            label="±3σ")
            lim = max(lim, min(3.0 * float(np.max(sd)), 3.0 * lim))
        ax.plot(t[s], e[s], color="tab:red" if ref == "truth" else "tab:purple", lw=0.8,
                label=f"estimate − {ref}")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylim(-max(lim, 1e-3), max(lim, 1e-3))
        rms = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
        ax.set_title(f"{est.estimator}: RMS {rms:.2f} m", fontsize=9)
        ax.tick_params(labelsize=8)
        if k % ncol == 0:
            ax.set_ylabel("alt error [m]", fontsize=8)
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
    for ax in axes[len(ests):]:
        ax.set_visible(False)
    for ax in axes[max(0, len(ests) - ncol):len(ests)]:
        ax.set_xlabel("time [s]", fontsize=8)
        ax.xaxis.set_tick_params(labelbottom=True)  # sharex hides them above an empty slot
    fig.suptitle(f"Altitude error vs {ref} — {drive.name}", fontsize=10)
    return _png(fig)


def plot_vertical_velocity_errors(drive: Drive, results: Sequence[Any]) -> bytes | None:
    """Vertical (down) velocity error of every estimator providing ``vel_d``, one axes."""
    ests = [e for e in _ok(results) if "vel_d" in e.provides]
    g = drive.gnss
    if not ests or (drive.truth is None and (g is None or g.vel_n is None)):
        return None
    fig = _figure(11.0, 3.6)
    ax = fig.subplots()
    _shade(ax, outage_windows(drive), label=True)
    ref = "truth" if drive.truth is not None else "GNSS"
    for est in ests:
        tr = est.trajectory
        if drive.truth is not None:
            t, _, e = truth_errors(est, drive)
        else:
            assert g is not None and g.vel_n is not None
            m = (g.t >= tr.t[0]) & (g.t <= tr.t[-1])
            t = g.t[m]
            e = np.interp(t, tr.t, tr.vel_down) - g.vel_n[m, 2]
        if e is None or not e.size:
            continue
        s = decimate(t.size)
        ax.plot(t[s], e[s], lw=0.7, label=f"{est.estimator} ({np.sqrt(np.mean(e**2)):.3f})")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("v_D error [m/s]")
    ax.set_title(f"Vertical velocity error vs {ref} (legend: RMS m/s) — {drive.name}",
                 fontsize=10)
    fig.subplots_adjust(right=0.8)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return _png(fig)


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
    fig = _figure(11.0, 3.2, left=0.1, wspace=0.45)
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
    return _png(fig)


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


def plot_baro_convergence(drive: Drive, results: Sequence[Any]) -> bytes | None:
    """Baro parameter estimates vs time (±1σ where known) with the truth, and the σ of the
    scale and latency from the covariance (log scale: how fast the data make them
    observable). None when no estimator provides any of these."""
    ests = _ok(results)
    hists = {e.estimator: h for e in ests if (h := baro_histories(e))}
    sds = {e.estimator: h for e in ests if (h := baro_sd_histories(e))}
    if not hists and not sds:
        return None
    panels = [("value", k) for k, _, _ in BARO_PARAMS if any(k in h for h in hists.values())]
    panels += [("sd", k) for k in ("scale", "latency_s") if any(k in h for h in sds.values())]
    fig = _figure(11.0, 0.6 + 2.1 * len(panels))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False).ravel()
    truth = baro_truth(drive)
    windows = outage_windows(drive)
    for ax, (kind, key) in zip(axes, panels, strict=True):
        label, sc = next((lb, s) for k, lb, s in BARO_PARAMS if k == key)
        _shade(ax, windows, label=False)
        if kind == "sd":
            for name, h in sds.items():
                if key in h:
                    t, sd = h[key]
                    s = decimate(t.size)
                    ax.plot(t[s], sd[s] * sc, lw=0.9, label=name)
            ax.set_yscale("log")
            ax.set_ylabel("σ of " + label, fontsize=8)
        else:
            for name, h in hists.items():
                if key not in h:
                    continue
                t, v, sd = h[key]
                s = decimate(t.size)
                (line,) = ax.plot(t[s], v[s] * sc, lw=0.9, label=name)
                if sd is not None:
                    ax.fill_between(t[s], (v[s] - sd[s]) * sc, (v[s] + sd[s]) * sc,
                                    color=line.get_color(), alpha=0.15, lw=0)
            if key == "bias_m" and drive.truth is not None and drive.truth.bias_baro is not None:
                s = decimate(drive.truth.t.size)
                ax.plot(drive.truth.t[s], drive.truth.bias_baro[s], "k--", lw=1, label="truth")
            elif truth[key] is not None:
                ax.axhline(truth[key] * sc, color="k", ls="--", lw=1, label="truth")
            ax.set_ylabel(label, fontsize=8)
        ax.legend(fontsize=7, ncol=5, loc="upper right")
        ax.tick_params(labelsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Baro parameter convergence (band: ±1σ; σ panels from the covariance)",
                 fontsize=10)
    return _png(fig)
