"""One self-contained HTML report: drive info, comparison table, baro parameters, plots.

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
.note{color:#555;font-size:0.85em}
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
            ("duration", f"{drive.duration_s:.1f} s"),
            ("IMU", f"{len(drive.imu)} samples, {drive.imu.rate_hz:.0f} Hz"),
            ("GNSS", "none" if drive.gnss is None else f"{len(drive.gnss)} fixes"),
            ("baro", "none" if drive.baro is None else f"{len(drive.baro)} samples")]
    for key in ("scenario", "seed", "imu_grade", "gnss_outages", "holdout_windows"):
        if key in drive.meta:
            rows.append((key.replace("_", " "), str(drive.meta[key])))
    if drive.baro_truth is not None:
        rows.append(("baro truth", f"scale {drive.baro_truth.scale * 100:.3f} %, latency "
                                   f"{drive.baro_truth.latency_s * 1000:.0f} ms"))
    return rows


def comparison_table(summary: dict[str, Any]) -> str:
    """HTML table of the per-estimator metrics of ``summary.json``."""
    head = ("<tr><th>estimator</th><th>status</th><th>alt RMSE [m]</th><th>alt max [m]</th>"
            "<th>v<sub>D</sub> RMSE [m/s]</th><th>NEES/dof</th><th>runtime [s]</th>"
            "<th>× real time</th></tr>")
    rows = []
    for name, m in summary["estimators"].items():
        nees = m["nees_mean"] / m["nees_dof"] if m.get("nees_dof") and m.get(
            "nees_mean") is not None else None
        cls = ' class="failed"' if m["status"] != "ok" else ""
        rows.append(
            f"<tr{cls}><td>{_e(name)}</td><td>{_e(m['status'])}</td>"
            f"<td>{_num(m['alt_rmse_m'], '.3f')}</td><td>{_num(m['alt_max_abs_m'], '.3f')}</td>"
            f"<td>{_num(m['vel_down_rmse_mps'], '.4f')}</td><td>{_num(nees, '.2f')}</td>"
            f"<td>{_num(m['runtime_s'], '.3f')}</td><td>{_num(m['realtime_factor'], '.0f')}</td>"
            "</tr>")
    return f"<table>{head}{''.join(rows)}</table>"


def baro_table(summary: dict[str, Any]) -> str:
    """HTML table of the baro parameters (estimate ± σ) per estimator, truth in the last row."""
    head = ("<tr><th>estimator</th><th>scale s [%]</th><th>latency τ<sub>d</sub> [ms]</th>"
            "<th>bias b [m]</th></tr>")
    rows, truth = [], None
    for name, m in summary["estimators"].items():
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


def render_html(summary: dict[str, Any], drive: Drive,
                images: Sequence[tuple[str, bytes]], version: str) -> str:
    """The report page. ``images``: (caption, PNG bytes), embedded in order."""
    d = summary["drive"]
    info = "".join(f"<tr><td>{_e(k)}</td><td>{_e(v)}</td></tr>" for k, v in drive_rows(drive))
    ref = ("truth (simulated drive)" if drive.truth is not None
           else "GNSS fixes (no truth: errors are against GNSS; use `vnav-graph holdout` for "
                "withheld-GNSS scores)")
    failed = [(n, m["error"]) for n, m in summary["estimators"].items() if m["status"] != "ok"]
    fail_html = "".join(f"<li><b>{_e(n)}</b>: {_e(err)}</li>" for n, err in failed)
    warned = [(n, w) for n, m in summary["estimators"].items() for w in m.get("warnings") or []]
    warn_html = "".join(f"<li><b>{_e(n)}</b>: {_e(w)}</li>" for n, w in warned)
    figs = "".join(
        f"<figure><img alt=\"{_e(cap)}\" src=\"data:image/png;base64,"
        f"{base64.b64encode(png).decode('ascii')}\"><figcaption>{_e(cap)}</figcaption></figure>"
        for cap, png in images)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>vnav-graph report — {_e(d['name'])}</title><style>{_CSS}</style></head>
<body>
<h1>vnav-graph report: {_e(d['name'])}</h1>
<p class="note">vnav_graph {_e(version)}; errors against {_e(ref)}.</p>
<h2>Drive</h2>
<table>{info}</table>
<h2>Comparison</h2>
{comparison_table(summary)}
<p class="note">NEES/dof: mean normalised estimation error squared per degree of freedom over
position/velocity (1 = consistent covariance). × real time: drive duration / runtime.</p>
{f'<h3>Failed estimators</h3><ul>{fail_html}</ul>' if failed else ''}
{f'<h3>Warnings</h3><ul>{warn_html}</ul>' if warned else ''}
<h2>Barometer parameters (estimate ± 1σ)</h2>
{baro_table(summary)}
<h2>Plots</h2>
{figs or '<p class="note">No estimate to plot.</p>'}
</body></html>
"""
