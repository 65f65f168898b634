"""``--config FILE.toml`` (estimator settings) and ``--plugin [NAME=]MODULE:CLASS`` (extension
estimators) on run / bench / holdout / list, and the same through the Python functions.

The extension used is the example's ``baro-only`` estimator (examples/ex_custom_estimator.py):
with ``calib_s`` shorter than one GNSS period it has fewer than two fixes to set its offset and
raises, which makes "the config reached the estimator" visible on every path.
"""

import json
import re
import sys
from pathlib import Path

import pytest

from vnav_graph.cli import main
from vnav_graph.estimators import base
from vnav_graph.estimators.configfile import load_configs
from vnav_graph.simulation import simulate

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ex_custom_estimator.py"
PLUGIN = f"{EXAMPLE}:BaroOnly"
TOO_SHORT = "fewer than 2 GNSS fixes"  # BaroOnly's error when calib_s holds < 2 fixes


@pytest.fixture(autouse=True)
def _clean_registry(monkeypatch, registry):
    """Plugins register into process-global state: undo it after each test."""
    monkeypatch.setattr(sys, "path", list(sys.path))


def _toml(tmp_path, text, name="cfg.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _one_line_error(capsys, rc):
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("vnav-graph: error: ") and err.count("\n") == 1, err
    return err


# --- --config -----------------------------------------------------------------------------


def test_load_configs_overrides_only_the_given_keys(tmp_path):
    from vnav_graph.estimators.ekf.filter import EkfConfig
    from vnav_graph.estimators.vertical.inputs import AhrsConfig
    from vnav_graph.estimators.vertical.loops import Loop3Config

    cfg = load_configs(_toml(tmp_path, "[loop3]\ntau = 40\ngains = [0.15, 0.0075, 1e-4]\n"
                                       "ahrs = { tilt_omega = 0.04 }\n"
                                       "[ekf]\ngate_prob = 0.999\n"))
    assert cfg["loop3"] == Loop3Config(tau=40.0, gains=(0.15, 0.0075, 1e-4),
                                       ahrs=AhrsConfig(tilt_omega=0.04))
    assert isinstance(cfg["loop3"].tau, float)  # a TOML integer given for a float field
    ekf = cfg["ekf"]
    assert ekf.gate_prob == 0.999 and cfg["loop3"].ahrs.tilt_omega == 0.04
    # untouched keys, also inside the nested config, keep the estimator's defaults
    assert cfg["loop3"].ahrs.yaw_gain == Loop3Config().ahrs.yaw_gain
    assert ekf.max_consecutive_rejects == EkfConfig().max_consecutive_rejects


def test_vekf7_takes_the_baro_prior_under_the_shared_names(tmp_path):
    # one name per quantity: the adaptive loop's and the shared settings' baro_* keys
    cfg = load_configs(_toml(tmp_path, "[vekf7]\nbaro_latency_mean = 0.2\nbaro_latency_sd = "
                                       "0.05\nbaro_scale_sd = 0.01\n[loop3-adaptive]\n"
                                       "baro_scale_sd = 0.01\n"))
    assert (cfg["vekf7"].baro_latency_mean, cfg["vekf7"].baro_latency_sd) == (0.2, 0.05)
    assert cfg["vekf7"].baro_scale_sd == cfg["loop3-adaptive"].baro_scale_sd == 0.01


def test_load_configs_sets_graph_isam2s_answer_settings(tmp_path):
    cfg = load_configs(_toml(tmp_path, "[graph-isam2]\nisam2_batch_fallback = true\n"
                                       "isam2_lag_s = 5\n"))["graph-isam2"]
    assert cfg.isam2_batch_fallback is True and cfg.isam2_lag_s == 5.0


@pytest.mark.parametrize("text, needle", [
    ("[graph-batchx]\nmax_iterations = 3\n", "unknown estimator [graph-batchx] (did you mean"),
    ("[graph-batch]\nmax_iter = 3\n", "[graph-batch] unknown key 'max_iter' (did you mean "
                                       "'max_iterations'?)"),
    ("[graph-batch]\nmax_iterations = 3.5\n", "max_iterations: expected int, got float"),
    ("[graph-batch]\ngravity_correction = 1\n", "gravity_correction: expected bool, got int"),
    ("[loop3]\ngains = [1.0, 2.0]\n", "gains: expected 3 values, got 2"),
    ("[loop3]\nahrs = { tilt_omegaa = 1.0 }\n", "unknown key 'ahrs.tilt_omegaa'"),
    ("[ekf]\ngate_prob = 2.0\n", "[ekf]: EkfConfig.gate_prob: must be in (0.5, 1)"),
    ("[graph-isam2]\nisam2_lag_s = -1.0\n", "isam2_lag_s must be a finite lag"),
    ("[graph-isam2]\nisam2_lag_s = 700.0\n", "must be shorter than isam2_window_s"),
    ("max_iterations = 3\n", "top-level key 'max_iterations' is not an [estimator] table"),
    ("[graph-batch\n", "not valid TOML"),
    ("[vekf7]\nlatency_prior = 0.2\n", "[vekf7] key 'latency_prior' is now 'baro_latency_mean'"),
])
def test_bad_config_is_one_line_exit_2_before_any_work(tmp_path, capsys, text, needle):
    out = tmp_path / "out"
    rc = main(["run", "--scenario", "hill-drive", "--duration", "30", "--estimators", "loop3",
               "--config", _toml(tmp_path, text), "--out", str(out)])
    assert needle in _one_line_error(capsys, rc)
    assert not out.exists()  # nothing ran, nothing written


def test_missing_config_file(tmp_path, capsys):
    rc = main(["bench", "--quick", "--config", str(tmp_path / "nope.toml"),
               "--out", str(tmp_path / "b")])
    assert "no such file" in _one_line_error(capsys, rc)


def test_config_changes_graph_batch_behaviour(tmp_path):
    """``[graph-batch] max_iterations = 1`` stops the solver at its cap; the warning names
    the way to raise it. (Without the file the same drive converges: test_graph.py.)"""
    out = tmp_path / "out"
    assert main(["run", "--scenario", "hill-drive", "--seed", "1", "--duration", "60",
                 "--estimators", "graph-batch", "--no-progress", "--out", str(out),
                 "--config", _toml(tmp_path, "[graph-batch]\nmax_iterations = 1\n")]) == 0
    block = json.loads((out / "summary.json").read_text())["estimators"]["graph-batch"]
    assert block["status"] == "ok"
    (w,) = block["warnings"]
    assert "stopped at max_iterations=1" in w
    assert "--config FILE.toml with [graph-batch] max_iterations = 100" in w
    # and what the model still expected: from the initial guess, far more than abs_tol
    m = re.search(r"model still predicted ([0-9.e+-]+) less", w)
    assert m is not None and float(m.group(1)) > 1.0


# --- --plugin -----------------------------------------------------------------------------


def test_plugin_from_a_file_is_listed(capsys):
    assert main(["list", "--plugin", PLUGIN]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(ln.split()[:2] == ["baro-only", "extension:"] for ln in lines)


def test_plugin_by_module_name_and_under_a_given_name(monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    assert main(["list", "--plugin", "ex_custom_estimator:BaroOnly",
                 "--plugin", "floor=ex_custom_estimator:BaroOnly"]) == 0
    names = [ln.split()[0] for ln in capsys.readouterr().out.splitlines()
             if ln.startswith("  ")]
    assert "baro-only" in names and "floor" in names


@pytest.mark.parametrize("spec, needle", [
    ("ex_custom_estimator", "expected [NAME=]MODULE:CLASS"),
    ("=ex_custom_estimator:BaroOnly", "expected [NAME=]MODULE:CLASS"),
    ("no_such_module_xyz:Thing", "cannot import no_such_module_xyz: ModuleNotFoundError"),
    (f"{EXAMPLE.parent / 'nope.py'}:X", "no such file"),
    (f"{EXAMPLE}:Nope", "has no class or factory 'Nope'"),
    (f"{EXAMPLE}:loop3_tau60", "has no string 'name' attribute; give one as NAME="),
    (f"ekf={EXAMPLE}:BaroOnly", "'ekf' is a built-in estimator"),
])
def test_bad_plugin_is_one_line_exit_2(capsys, spec, needle):
    assert needle in _one_line_error(capsys, main(["list", "--plugin", spec]))


def test_plugin_runs_with_its_config(tmp_path):
    """``run --plugin`` runs the extension like a built-in, and ``--config`` reaches it:
    calib_s = 10 s vs the default 30 s changes its offset estimate; 0.05 s (< one GNSS
    period at 10 Hz) makes it fail, reported in summary.json (exit 4: every estimator of the
    run failed; the summary is still written)."""
    def run(cfg, code=0):
        out = tmp_path / f"out{len(list(tmp_path.iterdir()))}"
        args = ["run", "--scenario", "hill-drive", "--seed", "2", "--duration", "60",
                "--estimators", "baro-only", "--plugin", PLUGIN, "--no-progress",
                "--out", str(out)]
        if cfg:
            args += ["--config", _toml(tmp_path, f"[baro-only]\n{cfg}\n", f"{out.name}.toml")]
        assert main(args) == code
        return json.loads((out / "summary.json").read_text())["estimators"]["baro-only"]

    default, short, broken = run(None), run("calib_s = 10"), run("calib_s = 0.05", code=4)
    assert default["status"] == short["status"] == "ok"
    assert short["baro"]["bias_m"]["est"] != default["baro"]["bias_m"]["est"]
    assert broken["status"] == "failed" and TOO_SHORT in broken["error"]


def test_config_reaches_holdout_and_bench(tmp_path, capsys):
    """The holdout and bench paths pass the config on too (bench: also echoed in bench.json
    and carried to the worker inside the task)."""
    from vnav_graph.io import save_npz
    from vnav_graph.run.bench import bench

    log = tmp_path / "log.npz"  # a drive without truth, as a real log
    save_npz(simulate("hill-drive", 3, duration_s=300.0).replace(truth=None), log)
    cfg = _toml(tmp_path, "[baro-only]\ncalib_s = 0.05\n")
    for extra, status in (([], "ok"), (["--config", cfg], "failed")):
        out = tmp_path / f"holdout-{status}"
        assert main(["holdout", str(log), "--estimators", "baro-only", "--plugin", PLUGIN,
                     "--out", str(out), *extra]) == 0
        held = json.loads((out / "holdout.json").read_text())["estimators"]["baro-only"]
        assert held["status"] == status and (status == "ok" or TOO_SHORT in held["error"])

    name = base.load_plugin(PLUGIN)
    doc = bench(["hill-drive"], [name], [0], duration_s=60.0, workers=1,
                configs=load_configs(cfg))
    assert doc["runs"][0]["status"] == "failed" and TOO_SHORT in doc["runs"][0]["error"]
    assert doc["config"]["estimator_configs"] == {name: {"calib_s": 0.05, "smooth_s": 2.0}}


def test_bench_cli_with_plugin_in_worker_processes(tmp_path, capsys):
    """A ``--plugin`` given as a file is importable in the bench's process-pool workers."""
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "--scenarios", "hill-drive", "--seeds", "2",
                 "--workers", "2", "--estimators", "baro-only", "--plugin", PLUGIN,
                 "--out", str(out)]) == 0
    runs = json.loads((out / "bench.json").read_text())["runs"]
    assert [r["status"] for r in runs] == ["ok", "ok"], runs
