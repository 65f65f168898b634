"""The corrupted-input corpus through the CLI's reading + validation path.

Every case (``corpus.build_cases``: >= 250 over the five formats) goes through
``load_drive`` (readers + ``vnav_graph.io.sanity``), which is what ``vnav-graph run`` does
before any estimator. Each must end as a one-line rejection or as a Drive that either carries
a warning or reads the same as its undamaged control (``oracle``): no tracebacks, no hangs, no
silent mis-reads. ``VNAV_FUZZ_REPORT=path.json`` writes every outcome to a file.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections import Counter
from pathlib import Path

import pytest

from .corpus import build_cases
from .oracle import FAILURES, Outcome, classify, load_with_limit

CASES = build_cases()
_CONTROLS: dict[str, object] = {}
_OUTCOMES: list[Outcome] = []


def _control(case, tmp: Path):
    if case.control is None:
        return None
    if case.control not in _CONTROLS:
        ctrl = next(c for c in CASES if c.id == case.control)
        try:
            _CONTROLS[case.control] = load_with_limit(ctrl.build(tmp / "control"))
        except ValueError:
            _CONTROLS[case.control] = None
    return _CONTROLS[case.control]


def run_case(case, tmp: Path) -> Outcome:
    control = _control(case, tmp)
    path = case.build(tmp / "case")
    t0 = time.perf_counter()
    try:
        drive = load_with_limit(path)
    except BaseException as exc:  # noqa: BLE001 - classified, re-raised for KeyboardInterrupt
        if isinstance(exc, KeyboardInterrupt):
            raise
        return classify(case, path, control, time.perf_counter() - t0, exc=exc)
    finally:
        shutil.rmtree(tmp / "case", ignore_errors=True)
    return classify(case, path, control, time.perf_counter() - t0, drive=drive)


def test_corpus_covers_every_format():
    fmts = Counter(c.fmt for c in CASES)
    assert set(fmts) == {"npz", "dataflash", "ulog", "sl-folder", "merged-csv"}
    # the always-present part (simulated base + tests/data cuts) alone is over 250 cases
    local = [c for c in CASES if "/sim/" in c.id or "-cut/" in c.id]
    assert len(local) >= 250
    assert all(n >= 20 for n in Counter(c.fmt for c in local).values())


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_case(case, tmp_path):
    o = run_case(case, tmp_path)
    _OUTCOMES.append(o)
    assert o.outcome not in FAILURES, (o.outcome, o.message or o.difference)


@pytest.fixture(scope="module", autouse=True)
def _report():
    """After the module's cases: counts by outcome and format (printed with -s) and, with
    $VNAV_FUZZ_REPORT, every outcome written to that file. A report, not a test."""
    yield
    if not _OUTCOMES:
        return
    table = Counter((o.fmt, o.outcome) for o in _OUTCOMES)
    lines = [f"{f:<11} {oc:<10} {n}" for (f, oc), n in sorted(table.items())]
    print("\n" + "\n".join(lines))
    out = os.environ.get("VNAV_FUZZ_REPORT")
    if out:
        Path(out).write_text(json.dumps([o.__dict__ for o in _OUTCOMES], indent=1))
