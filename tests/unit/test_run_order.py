"""First run: estimators whose kernels a second process compiles run last; results keep the
requested order."""

from __future__ import annotations

import pytest

from vnav_graph.run import runner
from vnav_graph.util import jit


@pytest.fixture
def ran(monkeypatch) -> list[str]:
    """The names ``runner.run_one`` is called with, in call order (nothing is run)."""
    calls: list[str] = []

    def fake_run_one(name, drive, config=None, waited_s=0.0, shared=None):
        calls.append(name)
        return runner.RunResult(name, None, "not run", 0.0, waited_s)

    monkeypatch.setattr(runner, "run_one", fake_run_one)
    return calls


class _FakePrewarm:
    families = ["ekf"]

    def __init__(self) -> None:
        self.waited: list[str] = []
        self.closed = False

    def wait(self, name: str) -> float:
        self.waited.append(name)
        return 0.0

    def close(self) -> None:
        self.closed = True


def test_child_families_run_last_and_results_keep_the_order(ran) -> None:
    pre = _FakePrewarm()
    names = ["loop2", "ekf", "ekf-rts", "graph-batch", "vkf4"]
    out = runner.run_estimators(None, names, progress=False, prewarm=pre)
    assert ran == ["loop2", "graph-batch", "vkf4", "ekf", "ekf-rts"]
    assert [r.name for r in out] == names
    assert pre.waited == ["loop2", "graph-batch", "vkf4", "ekf", "ekf-rts"] and pre.closed


class _Proc:
    def __init__(self, alive: bool) -> None:
        self.alive = alive

    def poll(self) -> int | None:
        return None if self.alive else 0


def _prewarm(alive: bool) -> jit.Prewarm:
    pre = object.__new__(jit.Prewarm)
    pre.families, pre.key, pre._warmed, pre.proc = ["ekf"], "k", set(), _Proc(alive)
    return pre


def test_warm_ups_run_here_when_the_child_is_still_compiling(monkeypatch) -> None:
    warmed: list[str] = []
    monkeypatch.setattr(jit, "run_warm_up", warmed.append)
    pre = _prewarm(alive=True)
    done = {"ekf": False}

    def is_warm(family: str, key: str | None = None) -> bool:
        return done.get(family, False)

    monkeypatch.setattr(jit, "is_warm", is_warm)
    # the child stamps the family while this process is busy with its warm-up
    monkeypatch.setattr(pre, "_until", lambda path, t0, timeout_s: done.update(ekf=True))
    assert pre.wait("loop2") == 0.0  # not the child's family: no wait, no warm-up
    pre.wait("ekf")
    pre.wait("ekf-rts")
    assert warmed == ["ekf-rts"]  # once, here, before the family's first estimator
    assert jit.CHILD_RUNS["ekf"] == ("ekf",)


def test_warm_ups_are_left_to_the_child_once_it_has_the_family(monkeypatch) -> None:
    warmed: list[str] = []
    waited_for: list[str] = []
    monkeypatch.setattr(jit, "run_warm_up", warmed.append)
    monkeypatch.setattr(jit, "is_warm", lambda family, key=None: True)
    pre = _prewarm(alive=True)
    monkeypatch.setattr(pre, "_until", lambda path, t0, timeout_s: waited_for.append(path.name))
    pre.wait("ekf")
    pre.wait("ekf-rts")
    assert warmed == []
    assert waited_for == ["ekf-k", "ekf-k", "warmup.ekf-rts-k"]


def test_rts_warm_up_compiles_the_signature_ekf_rts_uses() -> None:
    """The first-run prewarm compiles ``rts_smooth`` on a toy problem while the forward filter
    compiles elsewhere: wasted unless ekf-rts then calls it with the same argument types."""
    import warnings

    from vnav_graph.estimators.base import create
    from vnav_graph.estimators.ekf import rts
    from vnav_graph.simulation import simulate

    rts.warm_up()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        create("ekf-rts").run(simulate("default", 0, duration_s=20.0))
    assert len(rts.rts_smooth.signatures) == 1, rts.rts_smooth.signatures


def test_without_a_second_process_the_order_is_the_requested_one(ran) -> None:
    names = ["ekf", "loop2", "graph-batch"]
    out = runner.run_estimators(None, names, progress=False, prewarm=None)
    assert ran == names and [r.name for r in out] == names


def test_child_imports_the_package_this_process_imported(monkeypatch, tmp_path) -> None:
    """``python -m`` puts the working directory first on sys.path: from a clone after ``pip
    install .`` the child imported the clone's sources, whose kernels numba caches under
    another path, so the parent compiled everything again (fresh-clone CI: 104 s run). The
    child starts in the directory holding the package the parent imported."""
    import subprocess
    from pathlib import Path

    import vnav_graph

    seen: dict = {}

    class _Popen:
        def __init__(self, args, **kw) -> None:
            seen.update(kw, args=args)

    monkeypatch.setattr(subprocess, "Popen", _Popen)
    monkeypatch.chdir(tmp_path)
    jit.Prewarm(["ekf"], "k")
    assert seen["args"][1:4] == ["-m", "vnav_graph.util.jit", "k"]
    assert (Path(seen["cwd"]) / "vnav_graph" / "__init__.py").resolve() == \
        Path(vnav_graph.__file__).resolve()
