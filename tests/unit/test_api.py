"""The public Python API: ``from vnav_graph import ...`` names, imported lazily."""

import subprocess
import sys

import pytest

import vnav_graph

API = ("load_drive", "simulate", "create", "available", "register", "evaluate")


def test_import_does_not_load_heavy_dependencies():
    """``import vnav_graph`` (and so ``vnav-graph --help``) must not pull in scipy, numba or
    gtsam: a fresh interpreter, because this test process has long imported them."""
    code = ("import sys, vnav_graph; heavy = [m for m in ('numba', 'scipy', 'gtsam') "
            "if m in sys.modules]; print(','.join(heavy)); assert not heavy")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, f"imported at package import: {r.stdout.strip()} {r.stderr}"


@pytest.mark.parametrize("name", API)
def test_api_names_resolve_to_the_library_functions(name):
    from vnav_graph.estimators import base
    from vnav_graph.evaluation import metrics
    from vnav_graph.io import load_drive
    from vnav_graph.simulation import simulate

    expected = {"load_drive": load_drive, "simulate": simulate, "create": base.create,
                "available": base.available, "register": base.register,
                "evaluate": metrics.evaluate}[name]
    assert getattr(vnav_graph, name) is expected
    assert name in vnav_graph.__all__ and name in dir(vnav_graph)


def test_every_exported_name_resolves_and_unknown_names_raise():
    for name in vnav_graph.__all__:
        assert getattr(vnav_graph, name) is not None
    assert isinstance(vnav_graph.__version__, str)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        vnav_graph.nope  # noqa: B018


def test_api_round_trip_registers_and_creates():
    """register → available → create through the package namespace."""
    from vnav_graph import available, create, register

    class Dummy:
        name = "api-dummy"

        def __init__(self, config=None):
            self.config = config

    from vnav_graph.estimators.base import registry_snapshot

    with registry_snapshot():
        register("api-dummy", Dummy)
        assert "api-dummy" in available()
        assert create("api-dummy", {"k": 1}).config == {"k": 1}
    assert "api-dummy" not in available()  # the snapshot undid the registration
