"""Numba's on-disk cache and compile-time accounting.

Every numba kernel of vnav_graph is compiled with ``cache=True``. By default numba writes its
cache beside the source (``__pycache__`` inside the installed package). That breaks a later
``pip install -e`` over a ``pip install .``: pip removes the files it installed, the cache
folders stay behind, and Python then resolves ``vnav_graph`` to that leftover folder. So the
cache goes to the user's cache directory instead:

- ``$NUMBA_CACHE_DIR`` when the user set it (numba's own setting, honoured as is);
- otherwise ``<user cache dir>/vnav_graph/numba`` (``platformdirs.user_cache_dir``: e.g.
  ``~/.cache/vnav_graph/numba`` on Linux); ``$VNAV_CACHE_DIR`` replaces the
  ``<user cache dir>/vnav_graph`` part.

``configure_cache()`` is called by ``vnav_graph/__init__.py`` before any module imports numba;
it is cheap (no numba import). So is ``configure_opt()``, called there too: LLVM level 2
instead of numba's 3 unless ``NUMBA_OPT`` is set (the kernels run as fast, compile a tenth
faster). ``CompileTimer`` measures the time numba spends compiling (not loading from the
cache) inside a block, so that a run can report ``jit_s`` apart from ``runtime_s``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from types import TracebackType
from typing import Any


def cache_root() -> Path:
    """The package's cache directory (``$VNAV_CACHE_DIR`` or the platform user cache)."""
    env = os.environ.get("VNAV_CACHE_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("vnav_graph", appauthor=False))


KEEP_CACHES = 3  # source versions whose compiled kernels are kept side by side


def configure_cache() -> str:
    """Point numba's cache at the user cache directory unless ``NUMBA_CACHE_DIR`` is set.

    The directory is ``<cache>/numba/<source key>``: one per version of the package's
    sources. numba invalidates a cached kernel only when *its own* file changes; a kernel
    that calls a function of another module keeps the old callee (or, after a module moved,
    fails to load with ModuleNotFoundError). A fresh directory per source version rules that
    out; the ``KEEP_CACHES`` most recent are kept. Returns the directory in use. Works also
    when numba was imported first (its config module is then updated directly).
    """
    path = os.environ.get("NUMBA_CACHE_DIR")
    if not path:
        base = cache_root() / "numba"
        path = str(base / source_key())
        prune_old(base, Path(path))
    os.environ["NUMBA_CACHE_DIR"] = path
    cfg = sys.modules.get("numba.core.config")
    if cfg is not None and not getattr(cfg, "CACHE_DIR", ""):
        cfg.CACHE_DIR = path
    return path


# LLVM optimisation level for the package's kernels. numba's default is 3; level 2 compiles
# the first run's kernels ~10 % faster with the same run time (side by side, one process each,
# all ten estimators: compile 79.5 → 71.2 s of CPU, hill-drive run times equal to ±5 %; default
# run, empty cache, interleaved: 55.7 / 55.7 s wall at level 3 against 50.3 / 51.0 s at level
# 2). The kernels are scalar loops over small matrices, which level 3's extra passes (loop
# and SLP vectorisation) do not speed up.
NUMBA_OPT_LEVEL = "2"


def configure_opt() -> str | None:
    """Set numba's LLVM optimisation level (``NUMBA_OPT``) to ``NUMBA_OPT_LEVEL`` unless the
    user set it or numba is already imported (its config is then left alone: it applies to
    code outside this package too). Returns the level this process will use when known."""
    if "NUMBA_OPT" in os.environ:
        return os.environ["NUMBA_OPT"]
    if "numba" in sys.modules:
        return None
    os.environ["NUMBA_OPT"] = NUMBA_OPT_LEVEL
    return NUMBA_OPT_LEVEL


# a source version's directory used (written) this recently is never pruned [s]: two
# installed versions running at the same time (two virtual environments, a checkout and its
# CI) would otherwise delete each other's kernels while the other compiles into them
PRUNE_IDLE_S = 86_400.0


def prune_old(base: Path, current: Path) -> None:
    """Remove the source-version directories beyond the ``KEEP_CACHES`` most recently used
    that have not been written for ``PRUNE_IDLE_S``."""
    import time

    try:
        dirs = [d for d in base.iterdir() if d.is_dir() and d != current]
        mtimes = {d: d.stat().st_mtime for d in dirs}
    except OSError:
        return
    import shutil

    dirs.sort(key=lambda d: mtimes[d], reverse=True)
    now = time.time()
    for d in dirs[KEEP_CACHES - 1:]:
        if now - mtimes[d] > PRUNE_IDLE_S:
            shutil.rmtree(d, ignore_errors=True)


class CompileTimer:
    """Context manager: seconds numba spent compiling inside the block (``.seconds``).

    Cache loads are not compilation and are not counted. Without numba installed the count is
    0.0.
    """

    def __init__(self) -> None:
        self.seconds = 0.0
        self._ctx: Any = None
        self._listener: Any = None

    def __enter__(self) -> CompileTimer:
        try:
            from numba.core import event
        except ImportError:  # pragma: no cover - numba is a dependency
            return self
        self._listener = event.TimingListener()
        self._ctx = event.install_listener("numba:compile", self._listener)
        self._ctx.__enter__()
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._ctx is None:
            return
        self._ctx.__exit__(et, ev, tb)
        if self._listener.done:
            self.seconds = float(self._listener.duration)


# --- compiling in a second process -------------------------------------------------------------
# The first run on a machine compiles every kernel: 76 s of CPU for all estimators on this
# 2-core machine, measured side by side with the code before nav.arrays (97 s): ~28 s the
# vertical filters and their AHRS (was 44), ~41 s the EKF and its RTS (was 46), ~5 s the
# graph. Compilation holds the GIL and numba's compiler lock, so threads do not help; a
# second process does. ``Prewarm`` starts
# ``python -m vnav_graph.util.jit KEY FAMILY ...``, which runs the family's estimators on a short
# simulated drive (compiling their kernels into the shared on-disk cache) and leaves a stamp
# per family. ``runner.run_estimators`` runs the child's families last, so the main process
# compiles and runs every other estimator meanwhile, then waits for the stamp (``wait``) and
# loads the kernels from the cache. Default drive, empty cache, idle 2-core machine, one run
# each: 64.4 s with the EKF in the middle of the run order (the main process waited for the
# child half-way), 52.4 s with it last; warm 16.9 s. With the RTS kernel compiled here
# (``WARMUPS``), side by side on a slower hour: 74.7/73.3 s before, 70.3/70.6 s after;
# later, on a quieter hour, 58.9–64.0 s over five cold runs. Tried and dropped: running the
# vertical family after the graph's so that it loads the strapdown kernels the child has
# cached (its compile fell 17 → 11 s, the graph's rose 4 → 8.5 s; wall 59.6–67.5 s against
# 58.9–64.0 s). Then the EKF kernel lost three needless specialisations (np.cross, a read-only
# lever arm, a literal bool: its compile alone 48.5–49.6 → 41.8–42.8 s), the RTS warm-up went
# to whichever process is free first (``WARMUPS``), and the run path lost shared work (one
# AHRS for the vertical filters, no scipy.signal import, no interpreter teardown):
# ``bench_first_run.py`` in a fresh non-editable install, idle, 50.4–53.0 s cold over four
# runs against 60.5 and 62.3 s for the code before, interleaved; warm 10.4–12.8 s against
# 16.1–16.4 s. Two processes on this machine's two vCPUs each compile ~25 % slower than alone.

FAMILIES = {  # estimators that share kernels: compiled together, by one process
    "vertical": ("observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7"),
    "ekf": ("ekf-rts", "ekf"),
    "graph": ("graph-isam2", "graph-batch"),
}
PREWARM_DRIVE = ("default", 0, 30.0)  # scenario, seed, duration [s] of the compile drive


def package_root() -> Path:
    """The ``vnav_graph`` package directory this process imported."""
    return Path(__file__).resolve().parent.parent


def package_parent() -> str:
    """The directory holding the ``vnav_graph`` package this process imported."""
    return str(package_root().parent)


def family_of(name: str) -> str | None:
    return next((f for f, names in FAMILIES.items() if name in names), None)


def source_key() -> str:
    """Changes whenever a kernel's source may have changed (numba then recompiles): the hash
    of every module's path inside the package and its *content*, so that the same sources
    installed elsewhere or again (``pip install .``, then ``pip install -e .``) share one
    cache directory."""
    import hashlib

    from ..version import __version__

    h = hashlib.sha1(__version__.encode())
    root = package_root()
    for p in sorted(root.rglob("*.py")):
        h.update(f"{p.relative_to(root).as_posix()}:".encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


# numba's own cache locators, tried after the package's (numba.core.caching._CacheImpl)
NUMBA_LOCATORS = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator",
                  "IPythonCacheLocator", "ZipCacheLocator")


def configure_locator() -> bool:
    """Put ``PackageCacheLocator`` first in numba's cache locators
    (``NUMBA_CACHE_LOCATOR_CLASSES``, numba ≥ 0.62; older versions ignore it and cache by
    install path) unless the user set that variable. Cheap: numba is not imported."""
    if "NUMBA_CACHE_LOCATOR_CLASSES" in os.environ:
        return False
    value = ",".join((f"{__name__}.PackageCacheLocator", *NUMBA_LOCATORS))
    os.environ["NUMBA_CACHE_LOCATOR_CLASSES"] = value
    cfg = sys.modules.get("numba.core.config")
    if cfg is not None and hasattr(cfg, "CACHE_LOCATOR_CLASSES"):
        cfg.CACHE_LOCATOR_CLASSES = value
    return True


def __getattr__(name: str) -> Any:
    """``PackageCacheLocator`` is built on first use (numba imports it by name when it caches
    a kernel): defining it needs numba, which importing this module must not."""
    if name == "PackageCacheLocator":
        cls = package_locator()
        globals()[name] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def package_locator() -> type:
    """numba's cache locator for this package's kernels: the cache file sits under numba's
    cache directory at the kernel module's path *inside* the package (numba's own locator
    uses a hash of the absolute directory, so a reinstall at another path compiles again),
    and its freshness stamp is the SHA-256 of the module's content (not its mtime, which a
    reinstall changes). Modules outside the package get numba's locators."""
    import functools
    import hashlib

    from numba.core import config
    from numba.core.caching import UserProvidedCacheLocator

    root = package_parent()
    inside = os.path.join(root, "vnav_graph") + os.sep

    @functools.lru_cache(maxsize=256)
    def digest(path: str, mtime_ns: int, size: int) -> str:
        with open(path, "rb") as fh:
            return hashlib.sha256(fh.read()).hexdigest()

    class PackageCacheLocator(UserProvidedCacheLocator):  # type: ignore[misc]
        def __init__(self, py_func: Any, py_file: str) -> None:
            super().__init__(py_func, py_file)
            rel = os.path.relpath(os.path.dirname(os.path.abspath(py_file)), root)
            self._cache_path = os.path.join(config.CACHE_DIR, rel)

        def get_source_stamp(self) -> str:
            st = os.stat(self._py_file)
            return digest(self._py_file, st.st_mtime_ns, st.st_size)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if not os.path.abspath(py_file).startswith(inside):
                return None
            return super().from_function(py_func, py_file)

    PackageCacheLocator.__module__ = __name__
    return PackageCacheLocator


def stamp(family: str, key: str | None = None) -> Path:
    d = Path(configure_cache()) / "vnav-stamps"
    return d / f"{family}-{key or source_key()}"


def is_warm(family: str, key: str | None = None) -> bool:
    return stamp(family, key).exists()


# What the child runs to compile a family (default: every estimator of it), and the warm-ups:
# kernels an estimator needs that can be compiled on their own (the EKF's RTS kernel, about
# 5 s of the family's 41 s; ``ekf.rts.warm_up``). Whichever process is free first compiles
# them: this process, when it reaches the family before the child has compiled it (it then
# waits anyway), else the child, right after stamping the family (this process then runs
# ``ekf`` from the cache meanwhile and waits for the warm-up's stamp before ``ekf-rts``).
CHILD_RUNS = {"ekf": ("ekf",)}
WARMUPS = {"ekf-rts": ("vnav_graph.estimators.ekf.rts", "warm_up")}


def warm_ups_of(family: str) -> list[str]:
    """The estimators of ``family`` that have a ``WARMUPS`` hook."""
    return [name for name in FAMILIES[family] if name in WARMUPS]


class Prewarm:
    """Compile the kernels of some estimator families in a child process (see above)."""

    def __init__(self, families: list[str], key: str) -> None:
        import subprocess

        self.families, self.key = families, key
        self._warmed: set[str] = set()  # warm-ups compiled here
        # ``python -m`` puts the working directory first on sys.path: run from a clone after
        # ``pip install .`` (the README's first command), the child imported the clone's
        # sources while this process used the installed copy, compiled kernels that numba
        # caches per source path, and this process compiled them all again (fresh-clone CI:
        # 89 s of compilation in a 104 s run). The child starts in the directory that holds
        # the package this process imported.
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "vnav_graph.util.jit", key, *families], cwd=package_parent(),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    @classmethod
    def start(cls, names: list[str]) -> Prewarm | None:
        """A child compiling the second cold family of ``names`` (in run order) while this
        process compiles the others (measured on the default run: the EKF family alone costs
        about as much as the vertical filters, the graph's kernels a tenth of it). None when
        at most one family is cold. ``VNAV_PREWARM=0`` turns it off."""
        if os.environ.get("VNAV_PREWARM", "1") == "0":
            return None
        key = source_key()
        cold: list[str] = []
        for n in names:
            f = family_of(n)
            if f is not None and f not in cold and not is_warm(f, key):
                cold.append(f)
        if len(cold) < 2:
            return None
        try:
            return cls(cold[1:2], key)
        except OSError:
            return None

    def wait(self, name: str, timeout_s: float = 600.0) -> float:
        """Before running ``name``: wait until its kernels are compiled (by the child, or the
        child has died), compiling the family's ``WARMUPS`` here while the child still works
        on the family (see ``WARMUPS``). Returns the seconds spent."""
        import time

        f = family_of(name)
        if f not in self.families:
            return 0.0
        t0 = time.perf_counter()
        if not is_warm(f, self.key) and self.proc.poll() is None:
            for member in warm_ups_of(f):
                if member not in self._warmed:
                    self._warmed.add(member)
                    run_warm_up(member)
        self._until(stamp(f, self.key), t0, timeout_s)
        if name in WARMUPS and name not in self._warmed:
            self._until(stamp(f"warmup.{name}", self.key), t0, timeout_s)
        return time.perf_counter() - t0

    def _until(self, path: Path, t0: float, timeout_s: float) -> None:
        """Sleep until ``path`` exists, the child has exited or ``timeout_s`` has passed."""
        import time

        while (not path.exists() and self.proc.poll() is None
               and time.perf_counter() - t0 < timeout_s):
            time.sleep(0.05)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait()


def run_warm_up(name: str) -> None:
    """Run estimator ``name``'s ``WARMUPS`` hook (errors ignored: the real run reports them)."""
    hook = WARMUPS.get(name)
    if hook is None:
        return
    import importlib
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            getattr(importlib.import_module(hook[0]), hook[1])()
    except Exception:  # pragma: no cover - defensive: only the kernels matter here
        pass


def _compile_families(key: str, families: list[str]) -> None:
    """In the child: run each family's ``CHILD_RUNS`` estimators on a short drive (compiling
    their kernels into the cache), stamp the family, then compile its ``WARMUPS``."""
    import warnings

    from ..estimators.base import create
    from ..simulation import simulate

    scenario, seed, duration = PREWARM_DRIVE
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        drive = simulate(scenario, seed, duration_s=duration)
    for fam in families:
        for name in CHILD_RUNS.get(fam, FAMILIES[fam]):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    create(name).run(drive)
            except Exception:  # the real run reports errors; here only the kernels matter
                pass
        p = stamp(fam, key)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.touch()
        for name in warm_ups_of(fam):  # whether or not the parent has taken them (WARMUPS)
            run_warm_up(name)
            stamp(f"warmup.{name}", key).touch()


def mark_warm(names: list[str]) -> None:
    """After a run in this process: the families all of whose estimators ran are compiled."""
    key = source_key()
    for fam, members in FAMILIES.items():
        if set(members) <= set(names):
            try:
                p = stamp(fam, key)
                p.parent.mkdir(parents=True, exist_ok=True)
                p.touch()
            except OSError:
                pass


if __name__ == "__main__":  # pragma: no cover - exercised through Prewarm
    _compile_families(sys.argv[1], sys.argv[2:])
