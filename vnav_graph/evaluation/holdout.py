"""GNSS-outage holdout: a ground-truth-free accuracy measure for real logs.

GNSS is withheld inside outage windows; every estimator runs on the drive without those
fixes, and its altitude (and horizontal position, when it provides ``pos_h``) is scored
against the withheld fixes. This is the usual way to evaluate an aided INS without a
reference system (e.g. Groves, *Principles of GNSS, Inertial and Multisensor Integrated
Navigation*, 2nd ed., §14.4 on outage bridging; seed 004 reports outage altitude errors).

Scoring (stated in ``holdout.json["scoring"]``)
----------------------------------------------
For each estimator, with ĥ(t) its height at the GNSS fix times (the final trajectory
interpolated; a real-time answer, ``online`` or ``lag``, read from its latest epoch at or
before the fix and carried on at that epoch's velocity, ``held_forward``):

- datum offset ``c = median(h_gnss − ĥ)`` over the fixes the estimator *was given* (outside
  the windows). GNSS height and barometric height have different datums (MSL vs ellipsoid,
  weather), and a baro-only estimator can sit a constant away from the GNSS; that constant is
  not an outage error. ``c`` is reported per estimator (``alt_offset_m``).
- altitude error at each withheld fix: ``e = ĥ + c − h_gnss`` [m];
  ``alt_rmse_m = sqrt(mean e²)``, ``alt_max_abs_m = max |e|``.
- horizontal error (``pos_h`` estimators only): tangent-plane north/east difference to the
  withheld fix, no offset removed; ``horiz_rmse_m`` = RMS of its norm, else null.
- vertical-velocity error (``vel_d`` estimators, GNSS with velocity): ``v̂_D − v_D,GNSS`` at
  the withheld fixes, no offset removed; ``vel_down_rmse_mps`` = its RMS, else null.
- ``per_window``: the same three RMS values and the number of fixes per window (the blocks of
  the paired comparison in ``vnav_graph.evaluation.compare``).
- The withheld fixes are noisy themselves: the median reported vertical GNSS sigma inside the
  windows is given as ``gnss_sd_v_median_m``; an RMSE near it means "as good as GNSS".

Windows: length ``outage_s`` (default 60 s). The first starts after a lead-in of
``max(0.15·span, min(60 s, 0.25·span))`` of GNSS (estimators must initialise), the last ends
at least 5 s before the last fix. Default spacing (start to start) is
``max(2·outage, (span − lead − outage − 5 s)/4)``: up to five windows with at least one
outage length of GNSS between them.

``vnav_graph.run.runner.run_holdout`` runs the estimators on the withheld drive and scores them
here; ``vnav-graph holdout`` writes its ``holdout.json`` (``holdout_doc``), ``holdout.md``
(``format_markdown``, also printed) and ``holdout.png``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate, Trajectory
from ..types.streams import FloatArray
from .metrics import ONLINE_KEYS, causal_view, finite_max, finite_rms, known_after

HOLDOUT_SCHEMA = "vnav_graph.holdout/1"
TAIL_S = 5.0
MAX_WINDOWS = 5
_DOWN = ERROR_STATE["pos_n"].start + 2  # down-position row of the error state


@dataclass(frozen=True)
class Scored:
    """One estimator's holdout result (JSON block plus error series for the plot)."""

    block: dict[str, Any]
    t: FloatArray | None = None  # GNSS fix times [s]
    alt_err: FloatArray | None = None  # ĥ + c − h_gnss at every fix [m]
    withheld: np.ndarray | None = None  # (N,) bool: fix was withheld from the estimator
    alt_sd: FloatArray | None = None  # sqrt(P_DD + σ_GNSS,D²) at every fix [m], if cov
    horiz_err: FloatArray | None = None  # NE distance at withheld fixes, NaN elsewhere [m]
    vd_err: FloatArray | None = None  # v̂_D − v_D,GNSS at every fix [m/s]
    # sqrt(P_NN + P_EE + σ_GNSS,N² + σ_GNSS,E²) at every fix [m], pos_h estimates with a cov
    horiz_sd: FloatArray | None = None


@dataclass(frozen=True)
class HoldoutResult:
    doc: dict[str, Any]
    windows: list[tuple[float, float]]
    series: dict[str, Scored] = field(default_factory=dict)
    # the holdout run's trajectories (GNSS withheld in ``windows``) of the estimators that
    # provide a horizontal position, for the report's map
    trajectories: dict[str, Trajectory] = field(default_factory=dict)


def choose_windows(t_gnss: FloatArray, outage_s: float = 60.0,
                   spacing_s: float | None = None) -> list[tuple[float, float]]:
    """Outage windows ``[(t0, t1), ...]`` [s] over the GNSS span (see the module docstring).

    Raises ValueError when not even one window fits or the spacing is shorter than the outage.
    """
    if not outage_s > 0:
        raise ValueError(f"outage must be > 0 s, got {outage_s}")
    t_start, t_end = float(t_gnss[0]), float(t_gnss[-1])
    span = t_end - t_start
    lead = max(0.15 * span, min(60.0, 0.25 * span))
    last_end = t_end - TAIL_S
    if t_start + lead + outage_s > last_end:
        raise ValueError(f"GNSS span {span:.0f} s is too short for a {outage_s:g} s outage "
                         f"after a {lead:.0f} s lead-in (use a shorter --outage)")
    if spacing_s is None:
        spacing_s = max(2.0 * outage_s, (span - lead - outage_s - TAIL_S) / (MAX_WINDOWS - 1))
    elif spacing_s < outage_s:
        raise ValueError(f"spacing {spacing_s:g} s is shorter than the outage {outage_s:g} s")
    wins = []
    t0 = t_start + lead
    while t0 + outage_s <= last_end + 1e-9:
        wins.append((t0, t0 + outage_s))
        t0 += spacing_s
    return wins


# --outage lengths [s] ``windows_remedy`` tries, longest first
REMEDY_OUTAGES_S = (45.0, 30.0, 20.0, 15.0, 10.0)


def windows_remedy(t_gnss: FloatArray, outage_s: float, n_windows: int,
                   need: int = 4) -> str | None:
    """What would give ``need`` windows on this GNSS span: the longest ``--outage`` of
    ``REMEDY_OUTAGES_S`` (default spacing) that gives that many, or that none does; None when
    ``n_windows`` already reaches it."""
    if n_windows >= need:
        return None
    for o in REMEDY_OUTAGES_S:
        if o >= outage_s:
            continue
        try:
            n = len(choose_windows(t_gnss, o))
        except ValueError:
            continue
        if n >= need:
            return f"--outage {o:g} gives {n} windows on this log"
    span = float(t_gnss[-1] - t_gnss[0])
    return (f"this log's {span:.0f} s of GNSS holds fewer than {need} windows even of "
            f"{REMEDY_OUTAGES_S[-1]:g} s: a longer log would")


DEFAULT_OUTAGE_S = 60.0


def auto_outage(t_gnss: FloatArray, spacing_s: float | None = None,
                need: int = 4) -> tuple[float, str | None]:
    """The outage length ``run`` uses when none is given: ``DEFAULT_OUTAGE_S`` when it gives
    ``need`` windows (or more), else the longest of ``REMEDY_OUTAGES_S`` that does (the
    sentence that says so as second value); ``DEFAULT_OUTAGE_S`` and None when none does."""
    def count(o: float) -> int:
        try:
            return len(choose_windows(t_gnss, o, spacing_s))
        except ValueError:
            return 0

    n0 = count(DEFAULT_OUTAGE_S)
    if n0 >= need:
        return DEFAULT_OUTAGE_S, None
    for o in REMEDY_OUTAGES_S:
        n = count(o)
        if n >= need:
            return o, (f"outage {o:g} s chosen: it gives {n} windows on this log where "
                       f"{DEFAULT_OUTAGE_S:g} s gives {n0} (set --outage to choose)")
    return DEFAULT_OUTAGE_S, None


def in_windows(t: FloatArray, windows: Sequence[tuple[float, float]]) -> np.ndarray:
    m = np.zeros(np.shape(t), dtype=bool)
    for a, b in windows:
        m |= (t >= a) & (t <= b)
    return m


def withhold(drive: Drive, windows: Sequence[tuple[float, float]]) -> Drive:
    """The drive the estimators see: its GNSS fixes inside ``windows`` removed, the windows
    recorded in ``meta["gnss_holdout_windows"]``."""
    return drive.replace(gnss=drive.gnss.select(~in_windows(drive.gnss.t, windows)),
                         meta={**drive.meta, "gnss_holdout_windows": [list(w) for w in windows]})


def held_forward(tr: Trajectory, t_q: FloatArray, origin_lla: FloatArray) -> Trajectory:
    """``tr`` at times ``t_q`` (each at or after its first epoch) from its latest epoch at or
    before each, carried on at that epoch's velocity: a real-time answer read at an epoch
    between its own outputs, with nothing from the next one (linear interpolation would
    read up to one output interval ahead). Attitude and biases are held."""
    from ..geo.frames import lla_to_ned, ned_to_lla

    j = np.clip(np.searchsorted(tr.t, t_q, side="right") - 1, 0, tr.t.size - 1)
    tau = (t_q - tr.t[j])[:, None]
    if np.all(np.isfinite(tr.lla[:, :2])) and np.all(np.isfinite(tr.vel_n)):
        lla = ned_to_lla(lla_to_ned(tr.lla[j], origin_lla) + tr.vel_n[j] * tau, origin_lla)
    else:  # a vertical-only estimate: its height alone moves
        lla = tr.lla[j].copy()
        lla[:, 2] = tr.lla[j, 2] - np.nan_to_num(tr.vel_n[j, 2]) * tau[:, 0]

    def held(a: FloatArray | None) -> FloatArray | None:
        return None if a is None else a[j]

    return Trajectory(t_q, lla, tr.vel_n[j], held(tr.q_nb), held(tr.bias_gyro),
                      held(tr.bias_accel), held(tr.bias_baro))


def score(est: Estimate, drive: Drive, withheld: np.ndarray,
          windows: Sequence[tuple[float, float]] = (),
          given: np.ndarray | None = None, real_time: bool = False) -> Scored:
    """Score an estimate against the GNSS fixes flagged ``withheld`` (module docstring).

    ``windows`` (optional) adds ``per_window`` scores to the block. ``given``: the fixes the
    estimator was given (the datum offset is taken over them; default ``~withheld``) — a
    withheld fix excluded by the reference screen is in neither set. ``real_time``: read the
    estimate at each fix from its latest epoch at or before it (``held_forward``; its σ the
    same way) instead of interpolating between its epochs.
    """
    g = drive.gnss
    assert g is not None
    tr = est.trajectory
    inside = (g.t >= tr.t[0]) & (g.t <= tr.t[-1])
    t = g.t[inside]
    if real_time and t.size:
        tr = held_forward(tr, t, drive.origin_lla)
    h_g = g.lla[inside, 2]
    h_e = np.interp(t, tr.t, tr.alt)
    w = withheld[inside]
    seen = (~withheld if given is None else given)[inside]
    if not w.any():
        raise ValueError("estimate does not cover any withheld GNSS fix")
    c = float(np.median(h_g[seen] - h_e[seen])) if seen.any() else 0.0
    err = h_e + c - h_g
    e_w = err[w]
    horiz_err = np.full(t.size, np.nan)
    horiz = None
    if "pos_h" in est.provides and np.all(np.isfinite(tr.lla[:, :2])):
        from ..geo.frames import lla_to_ned

        lla_e = np.column_stack([np.interp(t[w], tr.t, tr.lla[:, j]) for j in range(3)])
        d = lla_to_ned(lla_e, drive.origin_lla)[:, :2] - lla_to_ned(
            g.lla[inside][w], drive.origin_lla)[:, :2]
        horiz_err[w] = np.sqrt(np.sum(d**2, axis=1))
        horiz = finite_rms(horiz_err[w])
    vd_err = None
    if "vel_d" in est.provides and g.vel_n is not None:
        vd_err = np.interp(t, tr.t, tr.vel_down) - g.vel_n[inside, 2]
    def var_at(rows: tuple[int, ...]) -> FloatArray | None:
        """Sum of the covariance diagonal ``rows`` at the fixes (held forward in real time)."""
        if est.cov is None or est.t_cov is None:
            return None
        var = sum(est.cov[:, r, r] for r in rows)
        ok = np.isfinite(var)
        if not ok.any():
            return None
        tc, vc = est.t_cov[ok], var[ok]
        v_t = (vc[np.clip(np.searchsorted(tc, t, side="right") - 1, 0, tc.size - 1)]
               if real_time else np.interp(t, tc, vc))
        return np.clip(v_t, 0.0, None)

    sd = None
    v_d = var_at((_DOWN,))
    if v_d is not None:
        sd = np.sqrt(v_d + g.pos_sd[inside, 2] ** 2)
    horiz_sd = None
    v_h = var_at((_DOWN - 2, _DOWN - 1)) if horiz is not None else None
    if v_h is not None:
        horiz_sd = np.sqrt(v_h + g.pos_sd[inside, 0] ** 2 + g.pos_sd[inside, 1] ** 2)
    rej = est.info.get("gnss_rejected") if est.info is not None else None
    block = {
        "status": "ok", "error": None,
        "alt_rmse_m": float(np.sqrt(np.mean(e_w**2))),
        "alt_max_abs_m": float(np.max(np.abs(e_w))),
        "horiz_rmse_m": horiz,
        "vel_down_rmse_mps": None if vd_err is None else finite_rms(vd_err[w]),
        "gnss_rejected": None if rej is None else int(rej),
        "gnss_forced": (None if est.info is None or est.info.get("gnss_forced") is None
                        else int(est.info["gnss_forced"])),
        "zupt_intervals": None if est.info is None else est.info.get("zupt_intervals"),
        "alt_offset_m": c,
        "n_scored": int(w.sum()),
        "runtime_s": float(est.runtime_s),
    }
    if windows:
        block["per_window"] = []
        for a, b in windows:
            m = w & (t >= a) & (t <= b)
            block["per_window"].append({
                "t0": float(a), "t1": float(b), "n": int(m.sum()),
                "alt_rmse_m": finite_rms(err[m]), "horiz_rmse_m": finite_rms(horiz_err[m]),
                "vel_down_rmse_mps": None if vd_err is None else finite_rms(vd_err[m])})
    return Scored(block, t, err, w, sd, horiz_err, vd_err, horiz_sd)


def check_run(scored: Scored, est: Estimate, held: Drive, drive: Drive, reference: np.ndarray,
              given: np.ndarray) -> None:
    """The self-check of one holdout run, into ``scored.block``: ``self_check`` (both answers
    against the fixes the run was given, ``selfcheck.check_answers`` on ``held``, whose
    withheld windows are outages; with ``error_max_m``, the largest errors of both answers
    in both axes against the withheld fixes), its flags added to ``warnings``, and
    ``status`` ``"diverged"`` with its ``error`` when the check fails or an answer is more
    than ``selfcheck.LOST_M`` from the withheld fixes (``selfcheck.far_off``)."""
    from .selfcheck import DIVERGED, check_answers, far_off

    b = scored.block
    view = causal_view(est, "online")
    check = check_answers(est, view, held)
    on_h = on_v = None
    if view is not None:
        try:
            o = score(view, drive, reference, given=given)
            on_v = o.block["alt_max_abs_m"]
            on_h = finite_max(o.horiz_err)
        except ValueError:  # covers no withheld fix
            pass
    maxima = {"height": b["alt_max_abs_m"], "horizontal": finite_max(scored.horiz_err),
              "online_height": on_v, "online_horizontal": on_h}
    b["self_check"] = {**check.as_dict(), "error_max_m": {**maxima, "basis": "withheld GNSS"}}
    b["warnings"] = [*b.get("warnings", []), *check.flags]
    far = far_off(maxima, "the withheld GNSS fixes")
    if check.diverged or far:
        b["status"], b["error"] = DIVERGED, check.reason or far


def causal_score(est: Estimate, drive: Drive, withheld: np.ndarray, which: str,
                 given: np.ndarray | None = None) -> dict[str, Any] | None:
    """The ``online`` / ``lag`` block of the holdout: the causal (or fixed-lag) estimate scored
    like the trajectory (``score``: its own datum offset, the same withheld fixes).
    ``heading_rmse_deg``, ``heading_known_rmse_deg`` and ``nees_*`` are null (GNSS gives
    neither a heading nor the full state); ``heading_known_after_s`` is the time [s after the
    drive's start] from which the estimate's own σ_yaw stays ≤ 5° (``metrics.known_after``,
    the summary's definition; it needs no reference); the lag block has ``lag_s``. None when
    the estimate has none (``causal_view``); null metrics when it covers no withheld fix."""

    view = causal_view(est, which)
    if view is None:
        return None
    out: dict[str, Any] = dict.fromkeys(ONLINE_KEYS)
    out["from_s"] = float(view.trajectory.t[0] - drive.imu.t[0])
    try:
        b = score(view, drive, withheld, given=given, real_time=True).block
    except ValueError:  # covers no withheld fix
        b = {}
    for k in ("alt_rmse_m", "horiz_rmse_m", "vel_down_rmse_mps"):
        out[k] = b.get(k)
    if "att" in view.provides:
        t = view.trajectory.t
        sd = view.sigma_at(t, ERROR_STATE["att_n"].start + 2)  # rotation error about down
        out["heading_known_after_s"] = known_after(
            t, None if sd is None else np.degrees(sd), t_ref=float(drive.imu.t[0]))
    if which == "lag":
        lag = est.info.get("lag_s")
        out["lag_s"] = None if lag is None else float(lag)
    return out


def baro_block(est: Estimate) -> dict[str, Any] | None:
    """Baro parameters of the holdout run: {name: {"est", "sd"}} (s [-], τd [s], b [m])."""
    if est.baro is None:
        return None
    out: dict[str, Any] = {}
    for k in ("scale", "latency_s", "bias_m"):
        p = getattr(est.baro, k)
        out[k] = None if p is None else {
            "est": float(p.est), "sd": None if p.sd is None else float(p.sd)}
    return out


def _onboard_score(drive: Drive, withheld: np.ndarray,
                   given: np.ndarray) -> dict[str, Any] | None:
    ob = drive.meta.get("onboard")
    if not ob or drive.gnss is None:
        return None
    t, alt = np.asarray(ob["t"], float), np.asarray(ob["alt"], float)
    g = drive.gnss
    inside = (g.t >= t[0]) & (g.t <= t[-1])
    w, seen = withheld & inside, given & inside
    if not w.any() or not seen.any():
        return None
    h_e = np.interp(g.t, t, alt)
    c = float(np.median(g.lla[seen, 2] - h_e[seen]))
    e = h_e[w] + c - g.lla[w, 2]
    return {"name": ob.get("name"), "saw_gnss": True,
            "note": "the autopilot had GNSS inside the windows: not an outage result",
            "alt_rmse_m": float(np.sqrt(np.mean(e**2))), "alt_max_abs_m": float(np.max(abs(e)))}


def holdout_doc(drive: Drive, windows: Sequence[tuple[float, float]], withheld: np.ndarray,
                reference: np.ndarray, screen: dict[str, Any], outage_s: float,
                results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The ``holdout.json`` document: the windows, the withheld fixes (``withheld``) and those
    that passed the reference screen (``reference``, ``screen``), one block per estimator
    (``results``: ``score(...).block`` or a failed block), the onboard estimate's score."""
    assert drive.gnss is not None
    sd_v = drive.gnss.pos_sd[withheld, 2]
    return {
        "schema": HOLDOUT_SCHEMA,
        "drive": {"name": drive.name, "source": drive.source,
                  "format": drive.meta.get("format"), "duration_s": drive.duration_s,
                  "height_reference": drive.meta.get("height_reference"),
                  "averaged_1s": drive.meta.get("averaged_1s")},
        "outage_s": float(outage_s),
        "spacing_s": None if len(windows) < 2 else float(windows[1][0] - windows[0][0]),
        "windows": [{"t0": a, "t1": b, "n_withheld": int(in_windows(drive.gnss.t, [(a, b)]).sum())}
                    for a, b in windows],
        "gnss_withheld": int(withheld.sum()),
        "reference_screening": screen,
        "gnss_sd_v_median_m": float(np.median(sd_v)) if sd_v.size else None,
        "scoring": ("alt error = estimate + c - withheld GNSS height at each withheld fix "
                    "that passes the reference screen (reference_screening), "
                    "c = median(GNSS height - estimate) over the fixes given to the estimator "
                    "(datum offset, reported as alt_offset_m); horiz error = NE distance to the "
                    "withheld fix, no offset removed; the final trajectory is interpolated "
                    "to the fix times, the online and lag answers are read from their "
                    "latest epoch at or before each fix, carried on at its velocity (nothing "
                    "from a later epoch)"),
        "estimators": results,
        "onboard": _onboard_score(drive, reference, ~withheld),
        # what would give enough windows to rank (``windows_remedy``), null when there are
        "remedy": windows_remedy(drive.gnss.t, outage_s, len(windows)),
    }


def _screen_note(sc: dict[str, Any] | None) -> str:
    if not sc or not sc.get("excluded"):
        return ""
    parts = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sc["by_check"].items() if v)
    return f" ({sc['excluded']} excluded as implausible references: {parts})"


def format_markdown(doc: dict[str, Any]) -> str:
    """Markdown table of a holdout document."""
    def f(v: Any, spec: str = ".2f") -> str:
        return "—" if v is None else format(v, spec)

    d = doc["drive"]
    lines = [
        f"# GNSS-outage holdout: {d['name']} ({d['format']}, {d['duration_s']:.0f} s)", "",
        f"{len(doc['windows'])} window(s) of {doc['outage_s']:g} s, "
        f"{doc['gnss_withheld']} GNSS fixes withheld"
        f"{_screen_note(doc.get('reference_screening'))}; median GNSS vertical sigma in the "
        f"windows {f(doc['gnss_sd_v_median_m'])} m. Scoring: {doc['scoring']}.", "",
        "| estimator | status | alt RMSE m | alt max m | horiz RMSE m | online alt RMSE m "
        "| online horiz RMSE m | GNSS rejected | offset m | run s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, b in doc["estimators"].items():
        status = b["status"] if b["error"] is None else f"{b['status']}: {b['error'][:60]}"
        on = b.get("online") or {}
        lines.append(f"| {name} | {status} | {f(b['alt_rmse_m'])} | {f(b['alt_max_abs_m'])} | "
                     f"{f(b['horiz_rmse_m'])} | {f(on.get('alt_rmse_m'))} | "
                     f"{f(on.get('horiz_rmse_m'))} | {f(b['gnss_rejected'], 'd')} | "
                     f"{f(b['alt_offset_m'])} | {f(b['runtime_s'])} |")
    ob = doc.get("onboard")
    if ob:
        lines.append(f"| onboard: {ob['name']} (had GNSS) | ok | {f(ob['alt_rmse_m'])} | "
                     f"{f(ob['alt_max_abs_m'])} | — | — | — | — | — | — |")
    if doc.get("reference"):
        lines += _reference_lines(doc, f)
    return "\n".join(lines) + "\n"


def _reference_lines(doc: dict[str, Any], f: Any) -> list[str]:
    """The windows scored against the reference (``evaluation.reference_score``)."""
    ref = doc["reference"]
    lines = ["", f"## Inside the windows, {ref['basis']} ({ref['format']}; {ref['time']}; "
             f"heights {ref['height']}; lever arm: {ref['lever_arm']})", "",
             "| estimator | n | alt RMSE m | alt max m | horiz RMSE m | horiz max m "
             "| vD RMSE m/s | NEES/dof |", "|---|---|---|---|---|---|---|---|"]
    for name, b in doc["estimators"].items():
        r = b.get("reference")
        if not r:
            continue
        nd = r["nees_mean"] / r["nees_dof"] if r.get("nees_dof") else None
        lines.append(f"| {name} | {r['n_scored']} | {f(r['alt_rmse_m'])} | "
                     f"{f(r['alt_max_abs_m'])} | {f(r['horiz_rmse_m'])} | "
                     f"{f(r['horiz_max_m'])} | {f(r['vel_down_rmse_mps'], '.3f')} | "
                     f"{f(nd)} |")
    return lines
