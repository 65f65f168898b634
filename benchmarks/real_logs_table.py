"""Regenerate the holdout table of ``docs/real_logs.md`` from the shared real logs.

    python benchmarks/real_logs_table.py [--data DIR] [--out DIR] [--no-write]

Runs ``vnav_graph.run.runner.run_holdout`` (60 s windows, default spacing, every
estimator, screened withheld GNSS) on each shared log present, writes
``DIR/real_logs_table.json`` (the holdout documents) and replaces the text between the
markers ``<!-- holdout-table:begin -->`` and ``<!-- holdout-table:end -->`` of
``docs/real_logs.md`` with the table, the real-log goals check (graph-batch against ekf-rts,
solver warnings, baro-scale agreement) and the screening counts.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root, present_logs, write_logs_json  # noqa: E402

NAMES = {"erle_pxf_218": "218", "erle_pxf_loiter_rtl": "loiter_rtl",
         "erle_pxf_181_gps_glitch": "181 glitch¹", "ski_iphone_100hz": "ski",
         "car_phone_1hz_2025-07-18": "car 07-18", "car_phone_1hz_2025-03-01a": "car 03-01a"}
BEGIN, END = "<!-- holdout-table:begin -->", "<!-- holdout-table:end -->"


def _cell(b: dict[str, Any]) -> str:
    if b.get("status") != "ok":
        return str(b.get("status"))
    a, h = b["alt_rmse_m"], b.get("horiz_rmse_m")
    return f"{a:.2f}" + ("" if h is None else f" / {h:.0f}")


def _scale(b: dict[str, Any]) -> tuple[float, float] | None:
    s = ((b.get("baro") or {}).get("scale")) or None
    return None if not s or s.get("sd") is None else (s["est"], s["sd"])


def render(docs: dict[str, dict[str, Any]]) -> str:
    cols = list(docs)
    ests = list(next(iter(docs.values()))["estimators"])
    out = ["| estimator | " + " | ".join(cols) + " |", "| --- " * (len(cols) + 1) + "|"]
    for e in ests:
        out.append(f"| {e} | " + " | ".join(_cell(docs[c]["estimators"].get(e, {}))
                                              for c in cols) + " |")
    ob = [docs[c].get("onboard") for c in cols]
    out.append("| onboard (autopilot, had GNSS) | " + " | ".join(
        "—" if not o else f"{o['alt_rmse_m']:.2f}*" for o in ob) + " |")
    out += ["", "Real-log goals (graph-batch against ekf-rts on screened withheld GNSS; "
            "baro scale s ± σ):", "",
            "| log | alt ratio (≤ 1.05) | horiz ratio (≤ 1.2) | solver warnings | "
            "s graph-batch | s graph-isam2 | s ekf-rts | batch vs isam2 [σ] | "
            "withheld / excluded |", "| --- " * 9 + "|"]
    for c in cols:
        E = docs[c]["estimators"]
        gb, gi, er = E.get("graph-batch", {}), E.get("graph-isam2", {}), E.get("ekf-rts", {})
        if gb.get("status") != "ok" or er.get("status") != "ok":
            out.append(f"| {c} | — | — | — | — | — | — | — | — |")
            continue
        ra = gb["alt_rmse_m"] / er["alt_rmse_m"]
        rh = (gb["horiz_rmse_m"] / er["horiz_rmse_m"]
              if gb.get("horiz_rmse_m") and er.get("horiz_rmse_m") else float("nan"))
        # solver warnings: the warnings that are not a baro prior conflict (a note on the
        # data, ``estimators.checks.prior_conflict_notes``; counted apart)
        notes = (gb.get("baro_prior_conflict") or []) + (gi.get("baro_prior_conflict") or [])
        warn = len([w for w in (gb.get("warnings") or []) + (gi.get("warnings") or [])
                    if w not in notes])
        warn_cell = f"{warn}" + (f" (+{len(notes)} prior conflict)" if notes else "")
        sb, si, se = _scale(gb), _scale(gi), _scale(er)

        def f(s: tuple[float, float] | None) -> str:
            return "—" if s is None else f"{100 * s[0]:+.1f} ± {100 * s[1]:.1f} %"

        z = "—" if sb is None or si is None else \
            f"{abs(sb[0] - si[0]) / max((sb[1] ** 2 + si[1] ** 2) ** 0.5, 1e-12):.1f}"
        sc = docs[c]["reference_screening"]
        out.append(f"| {c} | {ra:.2f} | {rh:.2f} | {warn_cell} | {f(sb)} | {f(si)} | {f(se)} | "
                   f"{z} | {sc['withheld']} / {sc['excluded']} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default="real-logs-table")
    ap.add_argument("--no-write", action="store_true", help="do not edit docs/real_logs.md")
    args = ap.parse_args(argv)
    from vnav_graph.io import load_drive
    from vnav_graph.run.runner import run_holdout

    root = data_root(args.data)
    docs: dict[str, dict[str, Any]] = {}
    for rel, p in present_logs(root):
        t0 = time.perf_counter()
        docs[NAMES[rel.split("/")[0]]] = run_holdout(load_drive(p), None, progress=True).doc
        print(f"{rel}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if not write_logs_json(docs, bool(docs), args.out, "real_logs_table.json"):
        return 2
    table = render(docs)
    print(table)
    if not args.no_write:
        md = Path(__file__).resolve().parents[1] / "docs" / "real_logs.md"
        text = md.read_text()
        if BEGIN not in text or END not in text:
            print(f"{md.name}: markers {BEGIN} / {END} not found", file=sys.stderr)
            return 2
        a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
        md.write_text(text[:a] + "\n" + table + "\n" + text[b:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
