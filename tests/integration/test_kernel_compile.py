"""The numba kernels stay cheap to compile (issue: a first run under a minute).

A slice assignment from an array (``out[k] = x``) makes numba compile a shape-mismatch error
that formats both shapes into a string, and ``np.linalg.solve`` / ``np.outer`` bring their
own wrappers: about a fifth of the cold compile of the default run, measured. The kernels use
``nav.arrays.put`` / ``solve`` / ``outer`` instead. The slow test compiles every estimator of
the default run with an empty numba cache, in a child process whose numba lowering is watched,
and lists every array-to-slice assignment lowered inside a vnav_graph kernel, and every numba
warning the compile raises.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.nav.arrays import outer, put, solve

_WATCH = r"""
import json, os, sys, warnings
from numba.core import event, types
import numba.np.arrayobj as ao

stack, hits = [], []

class Names(event.Listener):
    def on_start(self, ev):
        f = getattr(ev.data.get("dispatcher"), "py_func", None)
        stack.append(f"{f.__module__}.{f.__qualname__}" if f is not None else "")

    def on_end(self, ev):
        stack.pop()

orig = ao.fancy_setslice

def watched(context, builder, sig, args, index_types, indices):
    if isinstance(sig.args[2], types.Buffer):  # an array source: the formatted error
        frame, loc = sys._getframe(1), None
        while frame is not None and loc is None:
            low = frame.f_locals.get("self")
            if type(low).__name__ == "Lower":
                loc = low.loc
            frame = frame.f_back
        user = [s for s in stack if s.startswith("vnav_graph")]
        hits.append([user[-1] if user else "?",
                     f"{loc.filename}:{loc.line}" if loc is not None else "?"])
    return orig(context, builder, sig, args, index_types, indices)

ao.fancy_setslice = watched
event.register("numba:compile", Names())
from vnav_graph.estimators.base import create
from vnav_graph.simulation import simulate

with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    drive = simulate("default", 0, duration_s=30.0)
    for name in sys.argv[1:]:
        create(name).run(drive)
numba_warnings = sorted({str(w.message)[:300] for w in caught
                         if type(w.message).__module__.startswith("numba")})
print(json.dumps({"hits": hits, "numba_warnings": numba_warnings}))
"""

DEFAULT_RUN = ("observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7", "ekf",
               "ekf-rts", "graph-batch", "graph-isam2")


def test_put_copies_like_slice_assignment() -> None:
    a = np.zeros((3, 4))
    put(a[1], np.arange(4.0))
    put(a[:2, 2:], np.full((2, 2), 7.0))
    ref = np.zeros((3, 4))
    ref[1] = np.arange(4.0)
    ref[:2, 2:] = 7.0
    np.testing.assert_array_equal(a, ref)
    with pytest.raises(ValueError, match="shapes differ"):
        put(np.zeros(3), np.zeros(4))


def test_solve_and_outer_agree_with_numpy() -> None:
    rng = np.random.default_rng(7)
    for n in (1, 2, 6, 21):
        a = rng.normal(size=(n, n)) + n * np.eye(n)
        b = rng.normal(size=(n, 3))
        x = solve(a, b)
        np.testing.assert_allclose(a @ x, b, rtol=0, atol=1e-12 * n)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
        v = rng.normal(size=n)
        np.testing.assert_allclose(solve(a, v), np.linalg.solve(a, v), rtol=1e-10,
                                   atol=1e-12)
    # partial pivoting: a zero leading entry is no obstacle
    np.testing.assert_allclose(solve(np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([2.0, 3.0])),
                               [3.0, 2.0])
    with pytest.raises(np.linalg.LinAlgError):
        solve(np.zeros((2, 2)), np.ones(2))
    u, w = rng.normal(size=4), rng.normal(size=3)
    np.testing.assert_array_equal(outer(u, w), np.outer(u, w))


@pytest.mark.slow
def test_default_run_kernels_lower_no_array_slice_assignment(tmp_path: Path) -> None:
    import numba.np.arrayobj as ao

    if not hasattr(ao, "fancy_setslice"):
        pytest.skip("this numba has no arrayobj.fancy_setslice to watch")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "VNAV_PREWARM": "0"}
    r = subprocess.run([sys.executable, "-c", _WATCH, *DEFAULT_RUN], capture_output=True,
                       text=True, env=env, timeout=1800)
    assert r.returncode == 0, r.stderr[-2000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    hits = got["hits"]
    assert hits == [], "array-to-slice assignments in kernels (use nav.arrays.put): " + str(
        sorted({tuple(h) for h in hits}))
    # a cold compile warns nothing (a user saw "NumbaPerformanceWarning" in the ekf's warnings)
    assert got["numba_warnings"] == []
