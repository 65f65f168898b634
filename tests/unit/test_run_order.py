"""First run: estimators whose kernels a second process compiles run last; results keep the
requested order."""

from __future__ import annotations

from vnav_graph import pipeline


class _FakePrewarm:
    families = ["ekf"]

    def __init__(self) -> None:
        self.local = ["graph"]
        self.waited: list[str] = []
        self.closed = False

    def wait(self, name: str) -> float:
        self.waited.append(name)
        return 0.0

    def close(self) -> None:
        self.closed = True


def test_child_families_run_last_and_results_keep_the_order(monkeypatch) -> None:
    ran: list[str] = []

    def fake_run_one(name, drive, config=None, waited_s=0.0):
        ran.append(name)
        return pipeline.RunResult(name, None, "not run", 0.0, waited_s)

    monkeypatch.setattr(pipeline, "run_one", fake_run_one)
    pre = _FakePrewarm()
    names = ["loop2", "ekf", "ekf-rts", "graph-batch", "vkf4"]
    out = pipeline.run_estimators(None, names, progress=False, prewarm=pre)
    assert ran == ["loop2", "graph-batch", "vkf4", "ekf", "ekf-rts"]
    assert [r.name for r in out] == names
    assert pre.local == [] and pre.closed  # nothing left to compile while waiting


def test_without_a_second_process_the_order_is_the_requested_one(monkeypatch) -> None:
    ran: list[str] = []

    def fake_run_one(name, drive, config=None, waited_s=0.0):
        ran.append(name)
        return pipeline.RunResult(name, None, "not run", 0.0, waited_s)

    monkeypatch.setattr(pipeline, "run_one", fake_run_one)
    names = ["ekf", "loop2", "graph-batch"]
    out = pipeline.run_estimators(None, names, progress=False, prewarm=None)
    assert ran == names and [r.name for r in out] == names
