"""Causality of every online estimate on the drives where looking ahead pays: each causal
estimator (``base.CAUSAL`` and graph-isam2) run on a drive cut at T1 and on the same drive
cut later must give the same online answer at every epoch before T1 (the last one left out,
as in ``test_causality``).

The cases are the ones where an answer can take something from later data:
- ``glitch``: hill-drive with a 300 m, 8 s GNSS position glitch, cut inside it (a whole-drive
  glitch rule refuses the glitch only once its return is seen: graph-isam2 moved 289 m);
- ``standstill-mag``: hill-drive-mag standing still for its first 40 s, cut in the standstill
  (keyframe 0's compass heading from a tilt carried back from the first course: 3.9°);
- ``urban``: multipath bursts and signal losses, cut twice;
- ``long-outage``: a 90 s outage on a consumer IMU, cut inside it and after the return;
- ``1hz``: the 1 Hz phone receiver of cold-start-phone;
- ``hard``: urban under ``benchmarks/hard_scenarios.toml`` (Huber losses, the post-gates and
  ``gnss_gm_auto``, which decides from the whole drive: the real-time answers stay the first
  pass's, ``info["real_time_pass"]``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.integration.test_causality import differences
from vnav_graph.estimators.base import CAUSAL
from vnav_graph.estimators.configfile import load_configs
from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.run.runner import run_captured
from vnav_graph.simulation.scenario import load_scenario, simulate
from vnav_graph.types import Drive, Estimate
from vnav_graph.types.streams import GnssStream

pytestmark = pytest.mark.slow

ATOL_M = 1e-6  # height, north/east [m]; down velocity [m/s]
ATOL_DEG = 1e-6  # heading
HARD = Path(__file__).resolve().parents[2] / "benchmarks" / "hard_scenarios.toml"


def _glitch() -> Drive:
    d = simulate("hill-drive", 0, duration_s=90.0)
    g = d.gnss
    lla = g.lla.copy()
    m = (g.t >= g.t[0] + 55.0) & (g.t < g.t[0] + 63.0)
    lla[m, 0] += np.radians(300.0 / 111_320.0)
    return d.replace(gnss=GnssStream(g.t, lla, g.pos_sd, g.vel_n, g.vel_sd, g.lever_arm_b,
                                     g.spec))


def _scenario(name: str, seed: int, duration_s: float, **gnss: object) -> Drive:
    cfg = load_scenario(name, duration_s=duration_s)
    if gnss:
        cfg = replace(cfg, gnss=replace(cfg.gnss, **gnss))
    if name == "hill-drive-mag":
        cfg = replace(cfg, params={**cfg.params, "static_s": 40.0})
    return simulate(cfg, seed=seed)


# case: (drive, cuts [s from the start], configs by estimator name or None)
CASES = {
    "glitch": (_glitch, (58.0, 62.0), None),
    "standstill-mag": (lambda: _scenario("hill-drive-mag", 0, 75.0), (30.0, 60.0), None),
    "urban": (lambda: _scenario("urban", 2, 150.0), (70.0, 110.0), None),
    "long-outage": (lambda: _scenario("long-outage", 0, 160.0, outages=((40.0, 130.0),)),
                    (100.0, 140.0), None),
    "1hz": (lambda: _scenario("cold-start-phone", 0, 120.0), (60.0, 90.0), None),
    "hard": (lambda: _scenario("urban", 2, 150.0), (70.0, 110.0), "hard"),
}
NAMES = [*sorted(CAUSAL), "graph-isam2"]
_DRIVES: dict[str, Drive] = {}
_RUNS: dict[tuple[str, str, float | None], Estimate] = {}


def drive_of(case: str) -> Drive:
    if case not in _DRIVES:
        _DRIVES[case] = CASES[case][0]()
    return _DRIVES[case]


def run(case: str, name: str, t1: float | None) -> Estimate:
    """``name`` on the case's drive cut at ``t1`` (None: the whole drive)."""
    key = (case, name, t1)
    if key not in _RUNS:
        d = drive_of(case)
        if t1 is not None:
            d = d.until(float(d.imu.t[0]) + t1)
        cfg = None
        if CASES[case][2] == "hard":
            cfg = load_configs(HARD).get(name)
        _RUNS[key] = run_captured(name, d, cfg)
    return _RUNS[key]


@pytest.mark.parametrize("name, case", [(n, c) for n in NAMES for c in CASES])
def test_online_answer_does_not_change_when_the_drive_goes_on(case, name):
    d = drive_of(case)
    full = run(case, name, None)
    assert full.online is not None
    for t1 in CASES[case][1]:
        short = run(case, name, t1)
        assert short.online is not None
        # the drive's origin is its first fix's: the cut drive has the same one
        diff = differences(short.online, full.online, t1 - (short.online.t[0] - d.imu.t[0]),
                           d.origin_lla)
        for k, v in diff.items():
            assert v <= (ATOL_DEG if k == "heading" else ATOL_M), (t1, k, diff)


def test_the_glitch_case_holds_a_glitch_the_graph_refuses():
    """The glitch case has teeth: graph-isam2 refuses the glitch's fixes before its return
    (its online answer never follows them), and graph-batch, which may use the whole drive,
    refuses them too."""
    e = run("glitch", "graph-isam2", 62.0)
    assert e.info["gnss_rejected_pregate"] >= 60  # 7 s of 10 Hz fixes before the cut
    err = lla_to_ned(e.online.lla, drive_of("glitch").origin_lla)
    tr = drive_of("glitch").truth
    ref = lla_to_ned(np.column_stack([np.interp(e.online.t, tr.t, tr.lla[:, i])
                                      for i in range(3)]), drive_of("glitch").origin_lla)
    assert float(np.max(np.hypot(*(err - ref)[:, :2].T))) < 5.0


def test_a_whole_drive_decision_keeps_the_first_passes_real_time_answer():
    """Under the hard configuration the urban drive's GNSS residuals call for the GNSS error
    state (``gnss_gm_auto``); the decision is taken at the end of the drive, so the
    real-time answer is the first pass's and says so."""
    e = run("hard", "graph-isam2", None)
    dec = e.info["gnss_gm_auto"]
    assert dec["decided_at_s"] == pytest.approx(150.0, abs=0.5)
    if dec["on"]:
        assert e.info["real_time_pass"]["pass"] == "first"
    else:
        assert "real_time_pass" not in e.info
