"""Is the default real-log baro prior (``config.REAL_LOG_BARO``) honest?

Monte Carlo over simulated scenarios × seeds: each simulated drive is handed to the estimators
*as a real log* — its IMU and baro streams lose their spec (``spec=None``, what the log
readers give), so the estimators infer the IMU model from the data and take the baro prior
from ``REAL_LOG_BARO``, exactly as on a shared log — and the estimated baro scale, latency and
mean bias are compared with the simulation's truth: z = (estimate − truth) / σ, with the
estimate, σ and truth taken from the ``baro`` block of summary.json
(``vnav_graph.evaluation.blocks.baro_block``; bias truth = time average of b(t)). An honest σ
gives rms z ≈ 1 over the seeds; the goal is 0.8 ≤ rms z ≤ 1.25 for every
scenario × estimator × parameter. With n seeds the rms z of an exactly calibrated σ scatters:
``rms_z_ci95`` is its χ²(n) 95 % interval (assumes zero-mean Gaussian z; n = 20 gives
rms/1.31 … rms/0.69).

The scenarios run at their full durations (default 240 s, hill-drive 600 s, sortie 1200 s;
``--duration S`` shortens every one, e.g. for a smoke run). Runs are serial: one seed of the
three scenarios with ekf-rts and graph-batch takes about 35 s on one core, and on the shared
2-core machine a second worker would compete with the other users (``--workers 2`` halves
the wall time on an idle machine).

``--prior scale_sd=0.02,latency_mean=0.1,latency_sd=0.1,bias_sd=10,bias_tau=3600,noise_sd=0.5``
replaces ``REAL_LOG_BARO`` for this process only (to compare candidate priors before
changing the package default); every key is optional, unspecified ones keep the default.

Usage: python benchmarks/prior_study.py [--seeds 20] [--scenarios default,hill-drive,sortie]
           [--estimators ekf-rts,graph-batch] [--duration S] [--prior K=V,...] --out DIR
Writes DIR/prior_study.json (per scenario × estimator × parameter: n, rms z, mean z, its
interval, the rms error and median σ; the prior used; every run's numbers) and prints the
markdown table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

SCENARIOS = ("default", "hill-drive", "sortie")
ESTIMATORS = ("ekf-rts", "graph-batch")
PARAMS = ("scale", "latency_s", "bias_m")
GOAL = (0.8, 1.25)  # rms z of every baro parameter


def as_real_log(drive: Any, keep_imu_spec: bool = False) -> Any:
    """``drive`` as the log readers would give it: no IMU or baro spec (``spec=None``), so the
    estimators infer the IMU model and use ``REAL_LOG_BARO``. Truth stays (for scoring).
    ``keep_imu_spec`` (a diagnostic): the IMU keeps the simulation's spec."""
    baro = None if drive.baro is None else replace(drive.baro, spec=None)
    imu = drive.imu if keep_imu_spec else replace(drive.imu, spec=None)
    return drive.replace(imu=imu, baro=baro)


def z_scores(block: Mapping[str, Any]) -> dict[str, float | None]:
    """z = (est − truth) / sd per parameter of a summary.json ``baro`` block; None where the
    estimate, a positive finite sd or the truth is missing."""
    out: dict[str, float | None] = {}
    for p in PARAMS:
        b = block.get(p) or {}
        est, sd, tr = b.get("est"), b.get("sd"), b.get("truth")
        ok = (est is not None and tr is not None and sd is not None
              and np.isfinite(sd) and sd > 0 and np.isfinite(est) and np.isfinite(tr))
        out[p] = float((est - tr) / sd) if ok else None
    return out


def rms_stats(z: Sequence[float]) -> dict[str, Any]:
    """n, rms z, mean z and the χ²(n) 95 % interval of the rms (zero-mean Gaussian z)."""
    from scipy.stats import chi2

    a = np.asarray([x for x in z if x is not None and np.isfinite(x)], dtype=float)
    n = int(a.size)
    if n == 0:
        return {"n": 0, "rms_z": None, "mean_z": None, "rms_z_ci95": None}
    rms = float(np.sqrt(np.mean(a**2)))
    ci = [rms * float(np.sqrt(n / chi2.ppf(q, n))) for q in (0.975, 0.025)]
    return {"n": n, "rms_z": rms, "mean_z": float(np.mean(a)), "rms_z_ci95": ci}


def patch_prior(**kw: float) -> Any:
    """Replace ``REAL_LOG_BARO`` in every module that reads it (this process only) by a spec
    with the given ``scale_sd``, ``latency_mean``, ``latency_sd``, ``bias_sd``, ``bias_tau``,
    ``noise_sd``; returns the spec in force."""
    import importlib

    from vnav_graph import config

    base = config.REAL_LOG_BARO
    unknown = set(kw) - {"scale_sd", "latency_mean", "latency_sd", "bias_sd", "bias_tau",
                         "noise_sd"}
    if unknown:
        raise ValueError(f"--prior: unknown key(s) {sorted(unknown)}")
    lo, hi = base.latency_range_s
    mean = kw.pop("latency_mean", 0.5 * (lo + hi))
    sd = kw.pop("latency_sd", (hi - lo) / np.sqrt(12.0))
    spec = replace(base, latency_s=float(mean),
                   latency_range_s=(float(mean - np.sqrt(3.0) * sd),
                                    float(mean + np.sqrt(3.0) * sd)), **kw)
    for name in ("vnav_graph.config", "vnav_graph.sensors.model",
                 "vnav_graph.estimators.ekf.filter", "vnav_graph.estimators.graph.model.problem",
                 "vnav_graph.estimators.vertical.adaptive"):
        mod = importlib.import_module(name)
        if hasattr(mod, "REAL_LOG_BARO"):
            mod.REAL_LOG_BARO = spec
    return spec


def prior_used() -> dict[str, Any]:
    """The real-log baro spec in force and the prior every estimator reads from it."""
    from vnav_graph.sensors import model

    spec = model.REAL_LOG_BARO
    d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(spec).items()}
    return {"spec": d, "prior": asdict(model.baro_prior(spec))}


def run_one(scenario: str, seed: int, estimators: Iterable[str],
            overrides: Mapping[str, Any] | None = None,
            keep_imu_spec: bool = False) -> list[dict[str, Any]]:
    """Simulate ``scenario``/``seed``, run each estimator on it as a real log; one record per
    estimator: the ``baro`` block (est, sd, truth) and its z per parameter."""
    from vnav_graph.estimators.base import create
    from vnav_graph.evaluation.blocks import baro_block
    from vnav_graph.simulation import simulate

    truth_drive = simulate(scenario, seed, **dict(overrides or {}))
    drive = as_real_log(truth_drive, keep_imu_spec)
    rows = []
    for name in estimators:
        t0 = time.perf_counter()
        try:
            est = create(name).run(drive)
        except Exception as exc:  # a failure is a result of the study, not a crash of it
            rows.append({"scenario": scenario, "seed": seed, "estimator": name,
                         "status": "failed", "error": f"{type(exc).__name__}: {exc}"})
            continue
        block = baro_block(est.baro, truth_drive)
        rows.append({"scenario": scenario, "seed": seed, "estimator": name, "status": "ok",
                     "baro": block, "z": z_scores(block),
                     "runtime_s": time.perf_counter() - t0})
    return rows


def summarize(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """{scenario: {estimator: {param: rms_stats + rms_err + median_sd, failed}}}."""
    out: dict[str, Any] = {}
    keys = sorted({(r["scenario"], r["estimator"]) for r in rows},
                  key=lambda k: (SCENARIOS.index(k[0]) if k[0] in SCENARIOS else 99, k[1]))
    for sc, en in keys:
        sel = [r for r in rows if r["scenario"] == sc and r["estimator"] == en]
        ok = [r for r in sel if r["status"] == "ok"]
        block: dict[str, Any] = {"failed": len(sel) - len(ok)}
        for p in PARAMS:
            s = rms_stats([r["z"][p] for r in ok])
            err = [r["baro"][p]["est"] - r["baro"][p]["truth"] for r in ok
                   if r["z"][p] is not None]
            sds = [r["baro"][p]["sd"] for r in ok if r["z"][p] is not None]
            s["rms_err"] = float(np.sqrt(np.mean(np.square(err)))) if err else None
            s["median_sd"] = float(np.median(sds)) if sds else None
            block[p] = s
        out.setdefault(sc, {})[en] = block
    return out


def markdown(summary: Mapping[str, Any]) -> str:
    """rms z (mean z) per scenario × estimator × parameter; ✗ outside the goal band."""
    lines = ["| scenario | estimator | n | scale rms z (mean) | latency rms z (mean) | "
             "bias rms z (mean) |", "| --- | --- | --- | --- | --- | --- |"]
    for sc, ests in summary.items():
        for en, b in ests.items():
            cells = []
            for p in PARAMS:
                s = b[p]
                if s["rms_z"] is None:
                    cells.append("–")
                    continue
                mark = "" if GOAL[0] <= s["rms_z"] <= GOAL[1] else " ✗"
                cells.append(f"{s['rms_z']:.2f} ({s['mean_z']:+.2f}){mark}")
            n = max(b[p]["n"] for p in PARAMS)
            lines.append(f"| {sc} | {en} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def study(scenarios: Sequence[str], seeds: int, estimators: Sequence[str],
          overrides: Mapping[str, Any] | None = None, progress: str = "off",
          workers: int = 1, keep_imu_spec: bool = False) -> dict[str, Any]:
    """The whole study: every run's records, the summary and the prior used."""
    from vnav_graph.run.progress import Counter, steps

    jobs = [(sc, s) for sc in scenarios for s in range(seeds)]
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    if workers <= 1:
        for sc, s in steps(jobs, "prior study", progress, label=lambda j: f"{j[0]} seed {j[1]}"):
            rows += run_one(sc, s, estimators, overrides, keep_imu_spec)
    else:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        bar = Counter(len(jobs), "prior study", progress)  # type: ignore[arg-type]
        with ProcessPoolExecutor(workers) as pool:
            futs = {pool.submit(run_one, sc, s, list(estimators), overrides,
                                keep_imu_spec): (sc, s)
                    for sc, s in jobs}
            for f in as_completed(futs):
                rows += f.result()
                bar.update(f"{futs[f][0]} seed {futs[f][1]}")
        bar.close()
    rows.sort(key=lambda r: (r["scenario"], r["seed"], r["estimator"]))
    return {"schema": "vnav_graph.prior_study/1", "goal_rms_z": list(GOAL),
            "config": {"scenarios": list(scenarios), "seeds": seeds,
                       "estimators": list(estimators), "overrides": dict(overrides or {}),
                       "keep_imu_spec": keep_imu_spec,
                       "wall_s": time.perf_counter() - t0},
            "prior": prior_used(), "summary": summarize(rows), "runs": rows}


def _parse_prior(text: str) -> dict[str, float]:
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        k, _, v = item.partition("=")
        out[k.strip()] = float(v)
    return out


def main(argv: list[str] | None = None) -> int:
    from vnav_graph.run.progress import mode_for

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--duration", type=float, default=None,
                    help="override every scenario's duration_s [s]")
    ap.add_argument("--prior", default="", help="candidate REAL_LOG_BARO (module docstring)")
    ap.add_argument("--keep-imu-spec", action="store_true",
                    help="diagnostic: the IMU keeps the simulation's spec (only the baro is "
                         "disguised as a real log's)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error("--seeds: must be >= 1")
    if a.prior:
        patch_prior(**_parse_prior(a.prior))
        if a.workers > 1:
            ap.error("--prior patches this process only: use --workers 1")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    overrides = {} if a.duration is None else {"duration_s": a.duration}
    res = study([s for s in a.scenarios.split(",") if s], a.seeds,
                [e for e in a.estimators.split(",") if e], overrides,
                mode_for(not a.no_progress), a.workers, a.keep_imu_spec)
    (out / "prior_study.json").write_text(json.dumps(res, indent=1))
    print(markdown(res["summary"]))
    print(f"prior: {json.dumps(res['prior']['prior'])}")
    print(f"wrote {out / 'prior_study.json'} ({res['config']['wall_s']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
