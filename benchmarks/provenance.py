"""Where each section of ``docs/results.md`` comes from: the command, the commit and the time
of the run that wrote its JSON, and the JSON's sha256.

``make_results.py --run`` calls ``record`` around every step; it writes
``<results>/provenance.json``: ``{step: {"cmd", "commit", "dirty", "started_utc",
"finished_utc", "returncode"}}``. ``stamp`` turns one step into the line printed under its
section heading; ``keep`` copies a JSON small enough to commit into ``docs/results_data/``
(larger ones are named by their sha256 only).
"""

from __future__ import annotations

import datetime as dt
import gzip
import hashlib
import json
import subprocess
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
KEEP_MAX_BYTES = 400_000  # a JSON up to this size is committed beside the page


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True,
                           timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def _now() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")


def _portable(arg: str, i: int) -> str:
    """An argument as a reader can run it: the interpreter by name, paths inside the
    repository relative to it (no machine path in the page)."""
    if i == 0:
        return Path(arg).name
    root = str(REPO) + "/"
    return arg[len(root):] if arg.startswith(root) else arg


def record(results: Path, step: str, cmd: list[str], run: Any) -> int:
    """Run ``run()`` (returns an exit code) as ``step`` and record it in provenance.json."""
    # the page's own outputs (docs/) do not make the code dirty
    status = _git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs")
    entry: dict[str, Any] = {
        "cmd": " ".join(_portable(c, i) for i, c in enumerate(cmd)),
        "commit": _git("rev-parse", "HEAD"), "dirty": bool(status) if status is not None
        else None, "started_utc": _now()}
    rc = int(run())
    entry.update(finished_utc=_now(), returncode=rc)
    path = results / "provenance.json"
    doc = json.loads(path.read_text()) if path.is_file() else {}
    doc[step] = entry
    results.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return rc


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def keep(path: Path, into: Path, name: str) -> str:
    """Copy ``path`` to ``into/name`` when it is small, else gzipped to ``into/name.gz`` when
    that is small; the text naming the JSON (and its sha256) either way."""
    digest = sha256(path)
    raw = path.read_bytes()
    into.mkdir(parents=True, exist_ok=True)
    if len(raw) <= KEEP_MAX_BYTES:
        (into / name).write_bytes(raw)
        return f"JSON `docs/{into.name}/{name}` (sha256 `{digest[:16]}…`)"
    packed = gzip.compress(raw, mtime=0)
    if len(packed) <= KEEP_MAX_BYTES:
        (into / f"{name}.gz").write_bytes(packed)
        return (f"JSON `docs/{into.name}/{name}.gz` (gzip; sha256 of the JSON "
                f"`{digest[:16]}…`)")
    return (f"JSON `{path.name}` of {len(raw) / 1e6:.1f} MB, sha256 `{digest}` (too large to "
            "commit)")


def stamp(results: Path, step: str, kept: str, what: str) -> str:
    """The provenance line of one section: date, commit, command, what it covers (estimators,
    configuration, seeds: ``what``) and its JSON."""
    path = results / "provenance.json"
    entry = (json.loads(path.read_text()) if path.is_file() else {}).get(step)
    if entry is None:
        return (f"*Provenance:* {what}; {kept}; the run's date, commit and command were not "
                "recorded (page made from existing output).")
    commit = entry.get("commit") or "unknown"
    dirty = " with uncommitted changes" if entry.get("dirty") else ""
    return (f"*Provenance:* `{entry['cmd']}`, finished {entry['finished_utc']} at commit "
            f"`{commit[:10]}`{dirty}, exit {entry['returncode']}; {what}; {kept}.")
