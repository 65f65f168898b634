"""Blocks of the result documents that report what an estimator returned, not its errors:
the baro parameters (with their truth where the drive has one), the variables a graph
extension added, and ekf-rts's forward/backward separation (``summary.json``,
``holdout.json``, bench rows)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..types import BaroEstimate, Drive


def _param(block: Any, truth: float | None) -> dict[str, Any]:
    if block is None:
        return {"est": None, "sd": None, "truth": truth}
    return {"est": float(block.est), "sd": None if block.sd is None else float(block.sd),
            "truth": truth}


def baro_block(baro: BaroEstimate | None, drive: Drive) -> dict[str, Any]:
    """The ``baro`` block of summary.json. Bias truth is the time average of b(t)."""
    bt = drive.baro_truth
    bias_truth = None
    if drive.truth is not None and drive.truth.bias_baro is not None:
        bias_truth = float(np.mean(drive.truth.bias_baro))
    b = baro or BaroEstimate()
    return {
        "scale": _param(b.scale, None if bt is None else float(bt.scale)),
        "latency_s": _param(b.latency_s, None if bt is None else float(bt.latency_s)),
        "bias_m": _param(b.bias_m, bias_truth),
    }


def extra_variables_block(extra: Any) -> dict[str, Any] | None:
    """Value and σ of every added variable (``Estimate.info["extra_variables"]``; the
    covariance matrices stay in the estimate), None when there are none."""
    if not extra:
        return None
    return {str(k): {"est": [float(x) for x in v["est"]] if v.get("est") is not None else None,
                     "sd": [float(x) for x in v["sd"]]}
            for k, v in extra.items()}


# The error metrics of a summary.json / bench.json block, in their order: null until scored
# (``evaluate``), and null in the block of an estimator without a result
# (``runner.failed_block``)


def fb_separation_block(sep: Any) -> dict[str, float] | None:
    """``{"alt_p95_m", "horiz_p95_m"}``: the 95th percentiles of the distance between the
    forward filter and the filter run backward (``ekf.backward``); None when not computed."""
    if not sep:
        return None
    return {"alt_p95_m": float(sep["alt_p95_m"]), "horiz_p95_m": float(sep["horiz_p95_m"])}
