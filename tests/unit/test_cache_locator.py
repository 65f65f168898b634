"""Compiled kernels survive a reinstall elsewhere: the same sources at another path (``pip
install .`` into site-packages, then ``pip install -e .`` from the checkout) load their
kernels from the cache instead of compiling again (``jit.package_locator``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import vnav_graph
from vnav_graph.util import jit

PKG = Path(vnav_graph.__file__).resolve().parent

PROBE = """
import json, vnav_graph
from vnav_graph.util.jit import CompileTimer
with CompileTimer() as ct:
    from vnav_graph.nav.gaps import cv_bridge_noise
    cv_bridge_noise(0.1, 1.0)
import numba.core.config as c
print(json.dumps({"compile_s": ct.seconds, "file": vnav_graph.__file__,
                  "locators": c.CACHE_LOCATOR_CLASSES}))
"""


def _run(parent: Path, cache: Path) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES", "PYTHONPATH")}
    env.update(VNAV_CACHE_DIR=str(cache), PYTHONPATH=str(parent))
    r = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                       cwd=parent, timeout=300, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not hasattr(__import__("numba.core.config").core.config,
                                "CACHE_LOCATOR_CLASSES"),
                    reason="numba < 0.62 has no NUMBA_CACHE_LOCATOR_CLASSES: kernels are "
                           "cached by install path")
def test_the_same_sources_at_another_path_do_not_compile_again(tmp_path):
    a, b, cache = tmp_path / "a", tmp_path / "b", tmp_path / "cache"
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(PKG, a / "vnav_graph", ignore=ignore)
    first = _run(a, cache)
    assert first["file"].startswith(str(a)) and "PackageCacheLocator" in first["locators"]
    assert first["compile_s"] > 0.0  # an empty cache: the kernel is compiled
    shutil.copytree(PKG, b / "vnav_graph", ignore=ignore)  # new path, new mtimes
    second = _run(b, cache)
    assert second["file"].startswith(str(b))
    assert second["compile_s"] == 0.0
    # a changed kernel module is compiled again (content, not path, decides)
    gaps = b / "vnav_graph" / "nav" / "gaps.py"
    gaps.write_text(gaps.read_text() + "\n# changed\n")
    assert _run(b, cache)["compile_s"] > 0.0


def test_the_source_key_is_the_content_not_the_file_times(tmp_path):
    key = jit.source_key()
    os.utime(PKG / "version.py")  # a new mtime, the same content
    assert jit.source_key() == key
