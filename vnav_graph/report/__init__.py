"""Plots and the self-contained HTML report of one ``vnav-graph run``.

``write_report(out_dir, summary, results, drive, holdout=None)`` is called by
``pipeline.write_outputs`` (through ``cli.cmd_run``) with the temporary output directory; it
writes

- ``plots/altitude_error.png`` — altitude error per estimator, a row per family, ±3σ;
- ``plots/horizontal_error.png`` — horizontal error |ΔNE| per estimator, same layout, +3σ_h;
- ``plots/heading_error.png`` — heading (yaw) error per estimator against truth, ±3σ_yaw;
- ``plots/trajectory_map.png`` — north/east map: estimates, truth, GNSS fixes, outages;
- ``plots/vertical_velocity_error.png`` — vertical-velocity error, a panel per family;
- ``plots/baro_parameters.png`` — final baro scale/latency/bias ± 1σ (vs truth if simulated);
- ``plots/baro_convergence.png`` — baro parameter histories, when an estimator provides one;
- ``report.html`` — headline, comparison table, run/drive info, reader repairs, baro table and
  the plots embedded (base64).

The errors are on the basis of the table (:mod:`vnav_graph.report.errors`): truth for a
simulated drive; for a real log the errors of the holdout run at the withheld GNSS fixes
(``holdout`` = the ``holdout.HoldoutResult`` whose document ``pipeline.apply_holdout`` put in
the summary). Captions say which, and which windows are shaded.

Matplotlib is imported only inside the plotting modules (Agg canvas, no pyplot).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..types import Drive

# why an expected figure can be missing (said in the report instead of silently omitting it)
ABSENT = {"vertical_velocity_error.png": "No vertical-velocity plot: no estimator provides "
          "v_D, or there is no reference for it (a log whose GNSS has no velocity).",
          "altitude_error.png": "No altitude plot: no estimate to draw.",
          "horizontal_error.png": "No horizontal-error plot: no estimator provides a "
          "horizontal position.",
          "heading_error.png": "No heading-error plot: it needs a truth (GNSS gives no "
          "heading) and an estimator that provides the attitude."}


def captions(es: Any, summary: dict[str, Any]) -> dict[str, str]:
    """Figure captions that are true for this drive and error basis."""
    from .errors import GIVEN, TRUTH, WITHHELD

    n = len(es.windows)
    if es.basis == TRUTH:
        ref = "against the simulation truth"
        shade = (f"shaded: the {n} simulated GNSS outage(s)" if n
                 else "no GNSS outage in this drive")
        band = "dashed: ±3σ of the estimate's covariance, drawn where inside the axis"
    elif es.basis == GIVEN:
        ref = ("against the GNSS fixes the estimator was given (no holdout run: a fit "
               "residual, not a score; the table has no error numbers)")
        shade = f"shaded: {n} holdout window(s)" if n else "nothing shaded"
        band = "dashed: ±3σ of sqrt(P + σ_GNSS²), drawn where inside the axis"
    else:
        ev = summary.get("evaluation") or {}
        ref = ("of the holdout run against the GNSS fixes withheld from it, at those fixes "
               f"only (the basis of the table; {n} window(s) of {ev.get('outage_s', 0):g} s)")
        shade = "shaded: the withheld windows; the time axis shows only them"
        band = "dashed: ±3σ of sqrt(P + σ_GNSS²), drawn where inside the axis"
    grp = "grouped by family (smoothers, filters, loops/observers) with a shared y-scale"
    return {
        "altitude_error.png": f"Altitude error {ref}, one panel per estimator, {grp} per "
                              f"row; titles give the table's RMSE; {band}; {shade}.",
        "horizontal_error.png": f"Horizontal position error (norm of the north/east "
                                f"difference) {ref}, one panel per estimator that provides "
                                f"it, {grp} per row; titles give the table's RMSE; "
                                + "dashed: +3σ_h, σ_h = sqrt(P_NN + P_EE"
                                + (")" if es.basis == TRUTH else " + σ_GNSS,N² + σ_GNSS,E²)")
                                + f", drawn where inside the axis; {shade}.",
        "heading_error.png": f"Heading (yaw) error {ref}, one panel per estimator that "
                             f"provides the attitude, {grp} per row; titles give the table's "
                             "RMSE over the whole drive; dashed: ±3σ_yaw of the estimate, "
                             f"drawn where inside the axis; {shade}.",
        "trajectory_map.png": "Trajectory map, north/east of the origin [m] at equal scale: "
                              + ("the truth (black), " if es.basis == TRUTH else "")
                              + "the GNSS fixes (grey dots), "
                              + ("the truth inside the simulated GNSS outages (yellow), "
                                 if es.basis == TRUTH else
                                 "the fixes the holdout run withheld (orange crosses) and the "
                                 "holdout run's estimates (GNSS withheld in those windows), "
                                 if es.basis == WITHHELD else
                                 "the fixes inside the holdout windows (orange crosses; this "
                                 "run was given them), ")
                              + "each estimator that provides a horizontal position in its "
                              "colour and line style.",
        "vertical_velocity_error.png": f"Vertical (down) velocity error {ref}, {grp}; legend "
                                       f"gives the table's RMSE; {shade}.",
        "baro_parameters.png": "Barometer parameters: final estimate ± 1σ"
                               + (" vs truth" if es.basis == TRUTH else " (no truth)") + ".",
        "baro_convergence.png": "Barometer parameter histories (±1σ) and the σ of scale and "
                                "latency from the covariance; " + (
                                    shade if es.basis in (TRUTH, GIVEN) else
                                    "the run with all GNSS over the whole log; shaded: the "
                                    "windows in which the scoring run withheld GNSS") + ".",
        "fb_separation.png": "Forward/backward separation of ekf-rts: the distance between "
                             "its forward filter and the same filter run backward in time "
                             "(altitude and horizontal; dashed: the 95th percentiles in "
                             "fb_separation), a quality check that needs no truth.",
    }


def map_figure(drive: Drive, results: Sequence[Any], es: Any, holdout: Any) -> Any:
    """The trajectory map: the holdout run's tracks when there is one (with its withheld
    fixes marked), else the run's estimates that provide a horizontal position."""
    from .map_plot import plot_trajectory_map

    if holdout is not None and getattr(holdout, "trajectories", None):
        return plot_trajectory_map(drive, holdout.trajectories, es.windows,
                                   "GNSS fix withheld from the holdout run")
    tracks = {r.estimate.estimator: r.estimate.trajectory for r in results
              if r.estimate is not None and "pos_h" in r.estimate.provides}
    label = (None if drive.truth is not None
             else "GNSS fix inside a holdout window (given to this run)")
    return plot_trajectory_map(drive, tracks, es.windows, label)


def write_report(out_dir: str | Path, summary: dict[str, Any], results: Sequence[Any],
                 drive: Drive, holdout: Any = None) -> list[Path]:
    """Write the PNG plots under ``out_dir/plots`` and ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : directory to write into (created if missing)
    summary : the ``summary.json`` document (``pipeline.summarize`` / ``apply_holdout``)
    results : ``runner.RunResult`` list (estimate or error per estimator)
    drive : the drive the estimators ran on
    holdout : the ``HoldoutResult`` of a real log (its errors are drawn), or None

    Returns the written paths. A plot that fails is skipped with its error noted in the HTML
    (a figure must never cost the user the rest of the report).
    """
    from . import error_plots, plots
    from .errors import GIVEN, error_set
    from .html import render_html

    out = Path(out_dir)
    (out / "plots").mkdir(parents=True, exist_ok=True)
    es = error_set(drive, results, holdout)
    ests = summary["estimators"]

    def values(key: str) -> dict[str, Any]:
        return {} if es.basis == GIVEN else {n: m.get(key) for n, m in ests.items()}

    caps = captions(es, summary)
    todo: list[tuple[str, Callable[[], Any]]] = [
        ("altitude_error.png", lambda: error_plots.plot_altitude_errors(
            es, values("alt_rmse_m"), drive.name)),
        ("horizontal_error.png", lambda: error_plots.plot_horizontal_errors(
            es, values("horiz_rmse_m"), drive.name)),
        ("heading_error.png", lambda: error_plots.plot_heading_errors(
            es, values("heading_rmse_deg"), drive.name)),
        ("trajectory_map.png", lambda: map_figure(drive, results, es, holdout)),
        ("vertical_velocity_error.png", lambda: error_plots.plot_vertical_velocity_errors(
            es, values("vel_down_rmse_mps"), drive.name)),
        ("baro_parameters.png", lambda: plots.plot_baro_parameters(drive, results)),
        ("baro_convergence.png", lambda: plots.plot_baro_convergence(drive, results,
                                                                     es.windows)),
        ("fb_separation.png", lambda: plots.plot_fb_separation(results, es.windows)),
    ]
    written: list[Path] = []
    images: list[tuple[str, bytes]] = []
    failed: list[str] = []
    for fname, draw in todo:
        caption = caps[fname]
        try:
            fig = draw()
        except Exception as exc:  # noted in the report instead of aborting it
            failed.append(f"{fname}: not drawn ({type(exc).__name__}: {exc})")
            continue
        if fig is None:
            if fname in ABSENT:
                failed.append(ABSENT[fname])
            continue
        png, notes = (fig, ()) if isinstance(fig, bytes) else (fig.png, fig.notes)
        if notes:
            caption += " Notes: " + "; ".join(notes) + "."
        p = out / "plots" / fname
        p.write_bytes(png)
        written.append(p)
        images.append((caption, png))
    p = out / "report.html"
    p.write_text(render_html(summary, drive, images, failed), encoding="utf-8")
    written.append(p)
    return written


__all__ = ["captions", "map_figure", "write_report"]
