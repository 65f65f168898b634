"""One self-contained HTML report: headline, comparison table, run and drive info, reader
repairs, baro parameters, plots.

Images are embedded as ``data:image/png;base64`` URIs and the style sheet is inline, so the
file can be mailed or archived alone. All text taken from data (names, errors, metadata) is
HTML-escaped.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from typing import Any

from ..types import Drive

_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:0.6em 0 1.2em;font-size:0.88em}
th,td{border:1px solid #ccc;padding:3px 7px;text-align:right}
th{background:#f0f0f0} td:first-child,th:first-child{text-align:left}
tr.failed td{color:#a00} img{max-width:100%;border:1px solid #eee;margin:0.4em 0}
.note{color:#555;font-size:0.85em} td.best{font-weight:bold;background:#eef7ee}
tr.onboard td{color:#555;font-style:italic}
#headline{border-left:4px solid #2a7;padding:0.2em 0.8em;background:#f6fbf8}
.headline{font-size:1.05em;margin:0.35em 0} figcaption{font-size:0.85em;color:#333}
"""


def _e(x: Any) -> str:
    return html.escape(str(x))


def _num(v: Any, spec: str, scale: float = 1.0) -> str:
    return "—" if v is None else format(v * scale, spec)


def _pm(p: dict[str, Any], spec: str, scale: float) -> str:
    if p.get("est") is None:
        return "—"
    s = format(p["est"] * scale, spec)
    if p.get("sd") is not None:
        s += " ± " + format(p["sd"] * scale, spec)
    return s


def drive_rows(drive: Drive) -> list[tuple[str, str]]:
    """(label, value) pairs describing the drive."""
    rows = [("name", drive.name), ("source", drive.source),
            ("duration", f"{drive.duration_s:.1f} s (t = {drive.imu.t[0]:.2f} … "
                         f"{drive.imu.t[-1]:.2f} s, the IMU's span on the drive's clock)"),
            ("IMU", f"{len(drive.imu)} samples, {drive.imu.rate_hz:.0f} Hz"),
            ("GNSS", "none" if drive.gnss is None else f"{len(drive.gnss)} fixes"),
            ("baro", "none" if drive.baro is None else f"{len(drive.baro)} samples"),
            ("heights", drive.height_datum)]
    t0 = drive.meta.get("t0_unix_s")
    if t0 is not None:
        from datetime import UTC, datetime

        start = datetime.fromtimestamp(float(t0) + float(drive.imu.t[0]), UTC)
        rows.append(("start", f"{start:%Y-%m-%d %H:%M:%S} UTC (t = {drive.imu.t[0]:.2f} s on "
                              "the drive's clock)"))
    clock = drive.meta.get("clock")
    if clock:  # a log's time axis: the boot clock, or the boot clock rescaled to GPS seconds
        basis = clock.get("basis") if isinstance(clock, dict) else str(clock)
        rate = clock.get("boot_clock_per_gps_second") if isinstance(clock, dict) else None
        rows.append(("clock", str(basis) + (
            f" (the boot clock ran {(rate - 1) * 100:+.2f} % against GPS time)"
            if rate is not None and abs(rate - 1.0) > 1e-3 else "")))
    for key in ("imu_grade", "gnss_outages"):
        if key in drive.meta:
            rows.append((key.replace("_", " "), str(drive.meta[key])))
    if drive.baro_truth is not None:
        rows.append(("baro truth", f"scale {drive.baro_truth.scale * 100:.3f} %, latency "
                                   f"{drive.baro_truth.latency_s * 1000:.0f} ms"))
    return rows


# (summary key, header, format) of the comparison table; headers carry their unit
COLUMNS = (("status", "status", None), ("alt_rmse_m", "alt RMSE [m]", ".3f"),
           ("alt_max_abs_m", "alt max |err| [m]", ".3f"),
           ("horiz_rmse_m", "horiz RMSE [m]", ".3f"),
           ("vel_down_rmse_mps", "v<sub>D</sub> RMSE [m/s]", ".4f"),
           ("nees_per_dof", "NEES/dof", ".2f"), ("runtime_s", "runtime [s]", ".3f"),
           ("realtime_factor", "× real time", ".0f"))


def _cell(m: dict[str, Any], key: str, spec: str | None) -> str:
    if key == "nees_per_dof":
        v = (m["nees_mean"] / m["nees_dof"] if m.get("nees_dof") and m.get("nees_mean")
             is not None else None)
    else:
        v = m.get(key)
    return _e(v) if spec is None else _num(v, spec)


_BEST = ' class="best"'


def comparison_table(summary: dict[str, Any]) -> str:
    """HTML table of the per-estimator metrics of ``summary.json`` (``id="comparison"``;
    each header has ``data-key``, the summary key of its column), the autopilot's own
    estimate as a last row when the log has one. Rows are in family order."""
    from .groups import ordered

    head = "<tr><th>estimator</th>" + "".join(
        f'<th data-key="{k}">{h}</th>' for k, h, _ in COLUMNS) + "</tr>"
    best = {(m["best"], k) for k, m in ((summary.get("comparison") or {}).get("metrics")
                                        or {}).items() if m}
    rows = []
    for name in ordered(list(summary["estimators"])):
        m = summary["estimators"][name]
        cls = ' class="failed"' if m["status"] != "ok" else ""
        cells = "".join(
            f"<td{_BEST if (name, k) in best else ''}>{_cell(m, k, spec)}</td>"
            for k, _, spec in COLUMNS)
        rows.append(f'<tr{cls} data-name="{_e(name)}"><td>{_e(name)}</td>{cells}</tr>')
    ob = (summary.get("evaluation") or {}).get("onboard")
    if ob:
        cells = "".join(f"<td>{_cell(ob, k, spec) if k.startswith('alt') else '—'}</td>"
                        if k != "status" else "<td>had GNSS</td>" for k, _, spec in COLUMNS)
        rows.append(f'<tr class="onboard" data-name="onboard"><td>onboard: {_e(ob["name"])}'
                    f"*</td>{cells}</tr>")
    return f'<table id="comparison">{head}{"".join(rows)}</table>'


def rankings_html(summary: dict[str, Any]) -> str:
    """The real-time and offline rankings (``summary["rankings"]``) side by side, a table per
    metric (``id="rankings"``)."""
    from ..evaluation.compare import RANKING_METRICS, can_rank, ranked_name

    rk = summary.get("rankings")
    if not rk:
        return '<p class="note" id="rankings">No ranking: no estimator has a score.</p>'
    if not can_rank(summary):  # the headline says why, and what would resolve it
        return ('<p class="note" id="rankings">No ranking: too few paired blocks or windows '
                "to rank (see the headline).</p>")
    parts = []
    for key, label, unit in RANKING_METRICS:
        rt, off = rk["real_time"].get(key) or [], rk["offline"].get(key) or []
        if not rt and not off:
            continue
        spec = ".1f" if unit == "deg" else ".2f"

        def cell(rows: list[dict[str, Any]], i: int, spec: str = spec) -> str:
            return (f"<td>{_e(ranked_name(rows[i]))}</td><td>{_num(rows[i]['value'], spec)}</td>"
                    if i < len(rows) else "<td></td><td></td>")

        body = "".join(f"<tr><td>{i + 1}</td>{cell(rt, i)}{cell(off, i)}</tr>"
                       for i in range(max(len(rt), len(off))))
        parts.append(f'<table data-key="{key}"><tr><th colspan="5">{_e(label)} [{unit}]'
                     "</th></tr><tr><th>#</th><th>real time</th><th></th><th>offline</th>"
                     f"<th></th></tr>{body}</table>")
    return ('<div id="rankings"><p class="note">Real time: the causal estimates (each '
            "epoch from data up to it: filters, loops, observer, graph-isam2's online "
            "estimate; the ekf's from the end of its alignment). Offline: every trajectory, "
            "the smoothers' and graph-isam2's final one included. Lowest first; the paired "
            "comparison above says which differences are resolved.</p>"
            + "".join(parts) + "</div>")


def baro_table(summary: dict[str, Any]) -> str:
    """HTML table of the baro parameters (estimate ± σ) per estimator, truth in the last row."""
    head = ("<tr><th>estimator</th><th>scale s [%]</th><th>latency τ<sub>d</sub> [ms]</th>"
            "<th>bias b [m]</th></tr>")
    from .groups import ordered

    rows, truth = [], None
    for name in ordered(list(summary["estimators"])):
        m = summary["estimators"][name]
        b = m["baro"]
        truth = b
        if all(b[k]["est"] is None for k in ("scale", "latency_s", "bias_m")):
            continue
        rows.append(f"<tr><td>{_e(name)}</td><td>{_pm(b['scale'], '.3f', 100)}</td>"
                    f"<td>{_pm(b['latency_s'], '.0f', 1000)}</td>"
                    f"<td>{_pm(b['bias_m'], '.2f', 1)}</td></tr>")
    if truth is not None and any(truth[k]["truth"] is not None for k in truth):
        rows.append(f"<tr><th>truth</th><th>{_num(truth['scale']['truth'], '.3f', 100)}</th>"
                    f"<th>{_num(truth['latency_s']['truth'], '.0f', 1000)}</th>"
                    f"<th>{_num(truth['bias_m']['truth'], '.2f')}</th></tr>")
    if not rows:
        return '<p class="note">No estimator reported baro parameters.</p>'
    return f"<table>{head}{''.join(rows)}</table>"


def basis_text(summary: dict[str, Any]) -> str:
    """One sentence: what the errors in the table are measured against."""
    ev = summary.get("evaluation")
    ref = summary.get("reference")
    if ref:
        return (f"Errors are {ref['basis']} ({ref['format']}, {ref['epochs']} epochs) over the "
                f"whole drive: {ref['time']}; heights {ref['height']}; lever arm: "
                f"{ref['lever_arm']}. NEES/dof: mean normalised estimation error squared per "
                "degree of freedom over position/velocity (1 = consistent covariance).")
    if ev and ev.get("skipped"):
        return (f"No truth, and the withheld-GNSS scoring was skipped ({ev['skipped']}): the "
                "table has no error numbers, and the plots show fit residuals against the "
                "GNSS the estimators were given, not scores.")
    if ev:
        n = len(ev["windows"])
        sd = ev.get("gnss_sd_v_median_m")
        sd_txt = "" if sd is None else (f" The withheld fixes have a median vertical σ of "
                                        f"{sd:.2f} m: an RMSE near that is as good as GNSS.")
        return (f"Errors are against GNSS withheld in {n} window(s) of {ev['outage_s']:g} s "
                f"(a second run of every estimator without those fixes; {ev['scoring']}). "
                f"v<sub>D</sub> is against the withheld GNSS velocity; there is no truth, so "
                f"no NEES.{sd_txt}")
    if summary["drive"]["source"] == "simulated":
        return ("Errors are against the simulation truth over the whole drive. NEES/dof: mean "
                "normalised estimation error squared per degree of freedom over "
                "position/velocity (1 = consistent covariance).")
    return ("No truth and no holdout run: the table has no error numbers, and the plots show "
            "residuals against the GNSS the estimators were given (a fit, not a score). Run "
            "without --no-holdout to score against withheld GNSS.")


def headline_html(summary: dict[str, Any]) -> str:
    from ..evaluation.compare import headline_lines

    lines = headline_lines(summary)
    if not lines:
        why = ("fewer than two estimators have a score" if summary.get("comparison")
               or summary["drive"]["source"] == "simulated" or summary.get("reference")
               else "a log without truth is scored only by the holdout run (skipped here)")
        return f'<div id="headline"><p class="headline">No headline: {why}.</p></div>'

    *main, note = lines
    return ('<div id="headline">' + "".join(f'<p class="headline">{_e(x)}</p>' for x in main)
            + f'<p class="note">{_e(note)} {_e(summary["comparison"]["method"])}.</p></div>')


def run_rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """(label, value) pairs of the run: version, scenario, seed, scored windows."""
    rows = [("vnav_graph version", str(summary.get("version"))),
            ("scenario", "— (real log)" if summary.get("scenario") is None
             else str(summary["scenario"])),
            ("seed", "— (real log)" if summary.get("seed") is None else str(summary["seed"]))]
    ev = summary.get("evaluation")
    if ev and ev.get("skipped"):
        rows.append(("withheld-GNSS scoring", f"skipped: {ev['skipped']}"))
    elif ev:
        rows.append(("scored windows (withheld GNSS)", ", ".join(
            f"{w['t0']:.1f}–{w['t1']:.1f} s ({w['n_withheld']} fixes)" for w in ev["windows"])))
    return rows


def render_html(summary: dict[str, Any], drive: Drive,
                images: Sequence[tuple[str, bytes]], notes: Sequence[str] = ()) -> str:
    """The report page. ``images``: (caption, PNG bytes), embedded in order; ``notes``:
    plots that could not be drawn."""
    d = summary["drive"]
    info = "".join(f"<tr><td>{_e(k)}</td><td>{_e(v)}</td></tr>"
                   for k, v in run_rows(summary) + drive_rows(drive))
    failed = [(n, m["error"] if m["status"] == "failed" else f"{m['status']}: {m['error']}")
              for n, m in summary["estimators"].items() if m["status"] != "ok"]
    fail_html = "".join(f"<li><b>{_e(n)}</b>: {_e(err)}</li>" for n, err in failed)
    warned = [(n, w) for n, m in summary["estimators"].items() for w in m.get("warnings") or []]
    warn_html = "".join(f"<li><b>{_e(n)}</b>: {_e(w)}</li>" for n, w in warned)
    repairs = summary.get("repairs") or []
    rep_html = ("<ul id=\"repairs\">" + "".join(f"<li>{_e(r)}</li>" for r in repairs) + "</ul>"
                if repairs else '<p class="note" id="repairs">None (simulated drive, or the '
                "reader changed nothing).</p>")
    ob = (summary.get("evaluation") or {}).get("onboard")
    ob_html = (f'<p class="note">* {_e(ob["name"])}: the autopilot\'s own estimate, scored on '
               f"the same withheld fixes; {_e(ob['note'])}. Not ranked.</p>" if ob else "")
    figs = "".join(
        f"<figure><img alt=\"{_e(cap)}\" src=\"data:image/png;base64,"
        f"{base64.b64encode(png).decode('ascii')}\"><figcaption>{_e(cap)}</figcaption></figure>"
        for cap, png in images)
    figs = "".join(f'<p class="note">{_e(n)}</p>' for n in notes) + (
        figs or '<p class="note">No estimate to plot.</p>')
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>vnav-graph report — {_e(d['name'])}</title><style>{_CSS}</style></head>
<body>
<h1>vnav-graph report: {_e(d['name'])}</h1>
{headline_html(summary)}
<p class="note" id="basis">{basis_text(summary)}</p>
<h2>Comparison</h2>
{comparison_table(summary)}
{ob_html}
<h3>Rankings: real time and offline</h3>
{rankings_html(summary)}
{f'<h3>Failed estimators</h3><ul>{fail_html}</ul>' if failed else ''}
{f'<h3>Warnings</h3><ul>{warn_html}</ul>' if warned else ''}
<h2>Run and drive</h2>
<table>{info}</table>
<h3>Reader repairs and notes</h3>
{rep_html}
<h2>Barometer parameters (estimate ± 1σ)</h2>
{baro_table(summary)}
<h2>Plots</h2>
{figs}
</body></html>
"""
