"""First contact: fast help/list, --out checked before any work, progress without a terminal,
compile time reported apart from runtime, interrupts that leave nothing behind."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.run.outputs import TMP_PREFIX, check_out_dir, publish
from vnav_graph.util import jit


def _cli(*args: str, env: dict[str, str] | None = None, **kw) -> subprocess.CompletedProcess:
    full = {**os.environ, **(env or {})}
    if env and "VNAV_CACHE_DIR" in env:  # this process set NUMBA_CACHE_DIR when importing
        full.pop("NUMBA_CACHE_DIR", None)
    return subprocess.run([sys.executable, "-m", "vnav_graph", *args], capture_output=True,
                          text=True, env=full, **kw)


def test_help_and_list_import_no_numerics() -> None:
    """``--help`` and ``list`` must not load scipy, numba or gtsam (they cost seconds)."""
    code = ("import sys\nfrom vnav_graph.cli import build_parser, cmd_list\nbuild_parser()\n"
            "cmd_list(None)\nprint([m for m in ('scipy', 'numba', 'gtsam', 'pandas', "
            "'matplotlib') if m in sys.modules])")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip().splitlines()[-1] == "[]"
    assert "graph-batch" in r.stdout and "hill-drive" in r.stdout


@pytest.mark.parametrize("kind", ["file", "under_file"])
def test_bad_out_is_one_line_exit_2_before_any_work(tmp_path: Path, kind: str) -> None:
    f = tmp_path / "taken"
    f.write_text("not a directory")
    out = f if kind == "file" else f / "sub"
    r = _cli("run", "--out", str(out))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vnav-graph: error: --out"), r.stderr
    assert "simulating" not in r.stderr  # rejected before the drive was even simulated
    assert f.read_text() == "not a directory"


def test_unwritable_out_is_a_value_error(tmp_path: Path, monkeypatch) -> None:
    import tempfile

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(ValueError, match=r"cannot write in .* \(Permission denied\)"):
        check_out_dir(tmp_path / "new")
    assert not (tmp_path / "new").exists()


def test_publish_replaces_stale_results_and_dead_temp_folders(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "estimates").mkdir(parents=True)
    (out / "estimates" / "old-estimator.parquet").write_text("stale")
    (out / "notes.txt").write_text("the user's own file")
    dead = out / f"{TMP_PREFIX}999999999-abc"  # no such pid: a killed run's leftover
    dead.mkdir()

    def fill(tmp: Path) -> None:
        (tmp / "estimates").mkdir()
        (tmp / "estimates" / "ekf.parquet").write_text("new")
        (tmp / "summary.json").write_text("{}")

    written = publish(out, fill, ("estimates/*.parquet", "summary.json"))
    assert sorted(p.relative_to(out).as_posix() for p in written) == [
        "estimates/ekf.parquet", "summary.json"]
    assert not (out / "estimates" / "old-estimator.parquet").exists()
    assert (out / "notes.txt").read_text() == "the user's own file"
    assert not dead.exists()
    assert not list(out.glob(TMP_PREFIX + "*"))


def test_publish_failure_names_the_output_not_the_temp_folder(tmp_path: Path) -> None:
    def fill(tmp: Path) -> None:
        raise OSError(28, "No space left on device")

    with pytest.raises(ValueError) as ei:
        publish(tmp_path / "out", fill)
    assert str(tmp_path / "out") in str(ei.value) and TMP_PREFIX not in str(ei.value)
    assert "No space left" in str(ei.value)
    assert not list((tmp_path / "out").glob(TMP_PREFIX + "*"))


@pytest.mark.slow
def test_progress_lines_without_a_terminal(tmp_path: Path) -> None:
    r = _cli("run", "--estimators", "loop3,vkf4", "--duration", "40", "--out",
             str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    err = r.stderr.splitlines()
    assert any("estimators [1/2] loop3" in line for line in err)
    assert any("estimators [2/2] vkf4" in line for line in err)
    assert "estimators [" not in r.stdout  # progress never on stdout
    quiet = _cli("run", "--estimators", "loop3", "--duration", "40", "--no-progress",
                 "--out", str(tmp_path / "q"))
    assert quiet.returncode == 0 and quiet.stderr == ""


def test_stage_announces_only_slow_steps(capsys) -> None:
    from vnav_graph.run.progress import stage

    with stage("quick step", "lines", announce_after_s=0.5):
        pass
    with stage("slow step", "lines", announce_after_s=0.05):
        time.sleep(0.3)
    with stage("silent step", "off", announce_after_s=0.0):
        time.sleep(0.05)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "vnav-graph: slow step ..."
    assert err[1].startswith("vnav-graph: slow step: done in 0.")
    assert len(err) == 2


def test_compile_timer_counts_compilation_not_cache_loads() -> None:
    from numba import njit

    @njit  # a fresh function: compiled on its first call, not on the second
    def poly(x):
        s = 0.0
        for v in x:
            s += 3.0 * v * v - 2.0 * v + 1.0
        return s

    x = np.arange(10.0)
    with jit.CompileTimer() as first:
        assert poly(x) == pytest.approx(float(np.sum(3 * x * x - 2 * x + 1)))
    with jit.CompileTimer() as second:
        poly(x)
    assert first.seconds > 0.01
    assert second.seconds == 0.0


def test_numba_cache_goes_to_the_user_cache_dir(tmp_path: Path) -> None:
    code = ("import numba, vnav_graph, numba.core.config as c, os\n"
            "print(c.CACHE_DIR)\nprint(os.environ['NUMBA_CACHE_DIR'])")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["VNAV_CACHE_DIR"] = str(tmp_path / "c")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, check=True)
    # numba imported first: its config is updated all the same; one directory per version
    # of the package's sources (a kernel's cache is not invalidated when a callee in another
    # module changes or moves: after the estimators moved into subpackages, a cached EKF
    # smoother failed with ModuleNotFoundError)
    cfg_dir, env_dir = r.stdout.split()
    assert cfg_dir == env_dir and Path(cfg_dir).parent == tmp_path / "c" / "numba"
    assert Path(cfg_dir).name == jit.source_key()
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")  # the user's own setting wins
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, check=True)
    assert r.stdout.split() == [str(tmp_path / "mine")] * 2


def test_numba_opt_level_is_two_unless_the_user_chose() -> None:
    """``import vnav_graph`` before numba: LLVM level 2 (jit.NUMBA_OPT_LEVEL); the user's
    ``NUMBA_OPT`` wins; numba imported first: its config is not touched."""
    code = "import {first}, numba.core.config as c\nprint(int(c.OPT))"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_OPT"}

    def opt(first: str, **extra: str) -> str:
        r = subprocess.run([sys.executable, "-c", code.format(first=first)],
                           capture_output=True, text=True, env={**env, **extra}, check=True)
        return r.stdout.strip()

    assert opt("vnav_graph, numba") == "2" == jit.NUMBA_OPT_LEVEL
    assert opt("vnav_graph, numba", NUMBA_OPT="1") == "1"
    assert opt("numba, vnav_graph") == "3"  # numba's own default, left alone


def test_old_source_versions_are_pruned(tmp_path: Path) -> None:
    base = tmp_path / "numba"
    old = []
    for k in range(5):
        d = base / f"v{k}"
        d.mkdir(parents=True)
        os.utime(d, (1000.0 + k, 1000.0 + k))
        old.append(d)
    cur = base / "current"
    cur.mkdir()
    jit.prune_old(base, cur)
    kept = sorted(p.name for p in base.iterdir())
    # the current directory and the KEEP_CACHES − 1 most recently used others
    assert kept == ["current", "v3", "v4"] and jit.KEEP_CACHES == 3


def test_a_version_in_use_is_not_pruned(tmp_path: Path) -> None:
    """Directories written within PRUNE_IDLE_S stay, however many: another installed version
    running now compiles into one of them."""
    import time

    base = tmp_path / "numba"
    now = time.time()
    for k in range(5):
        d = base / f"v{k}"
        d.mkdir(parents=True)
        age = jit.PRUNE_IDLE_S * (2.0 if k == 0 else 0.5)  # v0 idle, the others in use
        os.utime(d, (now - age - k, now - age - k))
    cur = base / "current"
    cur.mkdir()
    jit.prune_old(base, cur)
    assert sorted(p.name for p in base.iterdir()) == ["current", "v1", "v2", "v3", "v4"]


def test_package_tree_holds_no_numba_cache() -> None:
    """The numba cache must never be written beside the sources (it breaks reinstalls)."""
    root = Path(jit.__file__).parent
    assert not [p for p in root.rglob("*.nb[ic]")]


@pytest.mark.slow
def test_run_reports_jit_apart_from_runtime(tmp_path: Path) -> None:
    """With an empty cache the compile time lands in ``jit_s``, not in ``runtime_s``: the
    cold runtime stays close to the warm one."""
    env = {"VNAV_CACHE_DIR": str(tmp_path / "cache"), "VNAV_PREWARM": "0"}
    docs = []
    for k in range(2):
        out = tmp_path / f"o{k}"
        r = _cli("run", "--estimators", "loop2,loop3", "--duration", "60", "--no-progress",
                 "--out", str(out), env=env)
        assert r.returncode == 0, r.stderr
        docs.append(json.loads((out / "summary.json").read_text())["estimators"])
    cold, warm = docs
    assert cold["loop2"]["jit_s"] > 0.3  # the shared vertical kernels compile here
    assert warm["loop2"]["jit_s"] == 0.0 and warm["loop3"]["jit_s"] == 0.0
    for n in ("loop2", "loop3"):
        assert cold[n]["runtime_s"] < 2 * warm[n]["runtime_s"] + 0.5


def test_sigint_during_run_leaves_no_output(tmp_path: Path) -> None:
    out = tmp_path / "o"
    p = subprocess.Popen([sys.executable, "-m", "vnav_graph", "run", "--out", str(out),
                          "--estimators", "ekf,ekf-rts,graph-batch", "--duration", "120"],
                         stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    t0 = time.time()
    for line in p.stderr:  # wait until an estimator is running
        if "estimators [2/3]" in line or time.time() - t0 > 120:
            break
    time.sleep(0.3)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())


def _interrupt_after(args: list[str], marker: str, delay_s: float = 0.3):
    p = subprocess.Popen([sys.executable, "-m", "vnav_graph", *args], stderr=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    t0 = time.time()
    for line in p.stderr:  # wait until the work is under way
        if marker in line or time.time() - t0 > 180:
            break
    time.sleep(delay_s)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    return p.returncode, err


def test_sigint_during_bench_records_what_finished(tmp_path: Path) -> None:
    out = tmp_path / "b"
    code, err = _interrupt_after(
        ["bench", "--quick", "--scenarios", "hill-drive", "--seeds", "4", "--estimators",
         "loop3,vkf4", "--workers", "1", "--out", str(out)], "bench [1/8]")
    assert code == 130, err
    assert "Traceback" not in err and "interrupted: wrote the" in err
    doc = json.loads((out / "bench.json").read_text())
    assert doc["config"]["interrupted"] is True and doc["config"]["runs_planned"] == 8
    assert 1 <= len(doc["runs"]) < 8
    assert all(r["status"] == "ok" for r in doc["runs"])  # finished runs, not killed ones
    assert not list(out.glob(".*tmp*"))


def test_sigint_during_holdout_leaves_no_output(tmp_path: Path) -> None:
    from vnav_graph.io import save_npz
    from vnav_graph.simulation import simulate

    d = simulate("hill-drive", 1, duration_s=400.0)
    log = tmp_path / "log.npz"
    save_npz(d.replace(truth=None, baro_truth=None), log)
    out = tmp_path / "h"
    code, err = _interrupt_after(["holdout", str(log), "--estimators", "ekf,ekf-rts,vkf4",
                                  "--out", str(out)], "holdout run [2/3]")
    assert code == 130, err
    assert "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())
