"""Output directories: checked before any work, filled atomically, never left half-written.

``check_out_dir(path)`` runs before a command does any work: ``--out`` must be a directory
(or not exist yet) on a writable file system, else one ``ValueError`` line (exit 2 through the
CLI) instead of a traceback after minutes of computation.

``publish(out_dir, fill)`` lets ``fill(tmp)`` write everything into a fresh temporary folder
``out_dir/.vnav-tmp-<pid>-*`` and then moves the files in under their final names, so an
interrupted run leaves no half-written file under a final name. Files of an earlier run that
this run owns the names of (``managed`` globs such as ``estimates/*.parquet``) but did not
write again are removed, so a directory reused for a run with fewer estimators does not keep
stale results beside the new summary. Temporary folders left by a killed run (their process
is gone) are removed on the next publish into the same directory.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

TMP_PREFIX = ".vnav-tmp-"
# ``estimates/<name>.online.parquet``: a causal estimator's online answer beside its final one
ONLINE_SUFFIX = ".online"


def check_out_dir(path: str | Path) -> Path:
    """Validate an output directory before any work (ValueError with one line if unusable).

    The directory is not created here: a run that fails on bad input leaves nothing behind.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    probe = out
    while not probe.exists():  # the nearest existing ancestor must take the new folder
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"--out {out}: {probe} is not a directory")
    try:
        fd, name = tempfile.mkstemp(prefix=TMP_PREFIX, dir=probe)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ValueError(f"--out {out}: cannot write in {probe} ({reason})") from None
    os.close(fd)
    os.unlink(name)
    return out


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    return True


def remove_dead_tmp(out_dir: Path) -> None:
    """Remove ``.vnav-tmp-<pid>-*`` folders whose process no longer runs."""
    for p in out_dir.glob(TMP_PREFIX + "*"):
        pid = p.name[len(TMP_PREFIX):].split("-", 1)[0]
        if p.is_dir() and (not pid.isdigit() or not _pid_alive(int(pid))):
            shutil.rmtree(p, ignore_errors=True)


def publish(out_dir: str | Path, fill: Callable[[Path], None],
            managed: Sequence[str] = ()) -> list[Path]:
    """Write through ``fill(tmp_dir)`` and move the files into ``out_dir`` (module docstring).

    Returns the final paths. An ``OSError`` while writing (disk full, permissions changed
    mid-run) becomes a one-line ``ValueError`` naming ``out_dir``, not the temporary folder.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        remove_dead_tmp(out)
        tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-", dir=out))
    except OSError as exc:
        raise ValueError(f"cannot write to {out}: {exc.strerror or type(exc).__name__}") from None
    try:
        fill(tmp)
        new = sorted(p for p in tmp.rglob("*") if p.is_file())
        rel = {p.relative_to(tmp) for p in new}
        written = []
        for p in new:
            dst = out / p.relative_to(tmp)
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(p, dst)
            written.append(dst)
        for pattern in managed:  # stale results of an earlier run in the same directory
            for old in out.glob(pattern):
                if old.is_file() and old.relative_to(out) not in rel:
                    old.unlink()
        return written
    except OSError as exc:
        raise ValueError(f"writing to {out} failed: {exc.strerror or type(exc).__name__}"
                         ) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
