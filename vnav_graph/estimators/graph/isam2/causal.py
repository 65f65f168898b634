"""graph-isam2's strictly causal online pass (``causal_pass``): keyframe 0 from the data
around keyframe 0 alone (``initial_guess.CausalStart``), and a restart from the full initial
guess once the heading is known. docs/graph.md, "Causal start"."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ....types import Drive
from ..model.extend import GraphExtension
from ..model.initial_guess import initial_states
from ..model.problem import setup
from ..settings import GraphConfig
from .online import OnlinePass, OnlineResult


def causal_pass(drive: Drive, cfg: GraphConfig, robust: bool,
                extensions: Sequence[GraphExtension]) -> tuple[OnlineResult, dict[str, Any]]:
    """The online pass, strictly causal from keyframe 0 on (``initial_guess.CausalStart``).

    When keyframe 0's heading is not known from the data around it (a standstill without a
    compass: the initial states carry the first TRIAD heading back to it with the gyro), the
    pass starts from the causal start with an uninformative yaw prior and runs up to the
    anchor keyframe m, where that heading becomes known; then it starts again from the
    initial states' keyframe 0 (the problem graph-batch solves) and runs the whole drive.
    The online estimate of keyframes 0 … m − 1 is the first pass's, from m on the second's
    (when the heading is never known, m is the last keyframe and the first pass is the whole
    online estimate).
    Returns the result and ``info["isam2_causal_start"]``."""
    P = setup(drive, cfg, causal=True)
    init = initial_states(P)
    st0 = P.start0
    info: dict[str, Any] = {"anchor_keyframe": None, "anchor_t_s": None,
                            "yaw_prior_sd_deg": float(np.degrees(st0.yaw_sd))}
    if st0.anchor is None:
        return OnlinePass(drive, cfg, robust, extensions, P, init, causal=True).run(), info
    m = st0.anchor
    # the first pass's online gate (``online_gate``) judged fixes from its own start: the
    # second pass, graph-batch's problem, starts from the same fixes as a pass of its own
    g_use0, rej0 = P.g_use.copy(), P.g_rej_post
    first = OnlinePass(drive, cfg, robust, extensions, P, init, causal=True)
    first.run_to(m)
    # (m is the last keyframe when the heading never becomes known: the first pass is then
    # the whole online estimate, the second one gives the final estimate)
    n_kept = m + 1 if m == P.n_kf - 1 else m
    answers = first.answers
    del first  # its iSAM2 is not alive under the second pass
    P.g_use[:], P.g_rej_post = g_use0, rej0
    again = OnlinePass(drive, cfg, robust, extensions, P, init)
    again.run_to(P.n_kf - 1)
    again.answers.keep(answers, n_kept)
    info.update(anchor_keyframe=m, anchor_t_s=float(P.t_kf[m] - P.t_kf[0]))
    return again.finish(), info
