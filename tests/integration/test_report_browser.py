"""The HTML report in a real headless browser: no console error, every image decoded, and a
full-page screenshot for the CI artefacts.

Chromium is driven through the DevTools protocol over ``--remote-debugging-pipe`` (file
descriptors 3 and 4, NUL-separated JSON), so no extra package is needed. The test skips when
``/usr/bin/chromium`` is absent (CI installs it with ``apt-get install -y chromium``). The
screenshot goes to ``$VNAV_ARTIFACTS`` (default: the test's temporary directory).
"""

from __future__ import annotations

import base64
import json
import os
import select
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.report import write_report
from vnav_graph.run.pipeline import RunResult, summarize
from vnav_graph.simulation import simulate

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--mute-audio"]
TIMEOUT_S = 60.0  # a cold Chromium start on a loaded 2-core CI machine takes several seconds
WIDTH = 1200


class Browser:
    """Minimal DevTools-protocol client over Chromium's debugging pipe."""

    def __init__(self, user_data_dir: Path) -> None:
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()

        def wire_fds() -> None:
            # the child must see the pipe ends as fd 3 (its input) and 4 (its output); dup2
            # makes them inheritable, every other pipe end is close-on-exec (Python's default)
            a, b = os.dup(to_chrome_r), os.dup(from_chrome_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        user_data_dir.mkdir(parents=True, exist_ok=True)
        self.log = user_data_dir.parent / "chromium-stderr.txt"  # a file: a pipe could fill up
        with open(self.log, "wb") as log:
            self.proc = subprocess.Popen(
                [str(CHROMIUM), *FLAGS, f"--user-data-dir={user_data_dir}",
                 "--remote-debugging-pipe", "about:blank"],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log,
                close_fds=False, preexec_fn=wire_fds)  # close_fds would undo wire_fds
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict[str, Any]] = []

    def _read_message(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._r], [], [], left)[0]:
                raise TimeoutError("no answer from Chromium")
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                err = self.log.read_text(errors="replace")
                raise RuntimeError(f"Chromium closed the pipe: {err[-500:]}")
            self._buf += chunk
        msg, _, self._buf = self._buf.partition(b"\0")
        return json.loads(msg)

    def send(self, method: str, params: dict[str, Any] | None = None,
             session: str | None = None) -> dict[str, Any]:
        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            m = self._read_message(deadline)
            if m.get("id") == self._id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m["result"]
            self.events.append(m)

    def wait_event(self, method: str) -> dict[str, Any]:
        for m in self.events:
            if m.get("method") == method:
                return m
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            m = self._read_message(deadline)
            self.events.append(m)
            if m.get("method") == method:
                return m

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._w)
        os.close(self._r)


def console_errors(events: list[dict[str, Any]]) -> list[str]:
    """Error-level console messages, uncaught exceptions and failed loads among the events."""
    out = []
    for m in events:
        p = m.get("params", {})
        if m.get("method") == "Runtime.exceptionThrown":
            out.append(str(p["exceptionDetails"].get("exception", {}).get("description")
                           or p["exceptionDetails"].get("text")))
        elif m.get("method") == "Runtime.consoleAPICalled" and p.get("type") in (
                "error", "assert"):
            out.append(" ".join(str(a.get("value", a.get("description"))) for a in p["args"]))
        elif m.get("method") == "Log.entryAdded" and p["entry"]["level"] == "error":
            out.append(p["entry"]["text"])
    return out


IMAGE_CHECK = """Promise.all(Array.from(document.images).map(img =>
  img.decode().then(() => null, e => String(e)).then(err => ({
    alt: img.alt.slice(0, 60), w: img.naturalWidth, h: img.naturalHeight, err}))))"""


def load_report(html: Path, shot: Path, tmp: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """Open ``html`` (file:// URL), return (images, console errors), save a full-page PNG."""
    b = Browser(tmp / "chromium-profile")
    try:
        target = b.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        s = b.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            b.send(f"{domain}.enable", session=s)
        b.send("Emulation.setDeviceMetricsOverride",
               {"width": WIDTH, "height": 900, "deviceScaleFactor": 1, "mobile": False},
               session=s)
        b.send("Page.navigate", {"url": html.resolve().as_uri()}, session=s)
        b.wait_event("Page.loadEventFired")
        images = b.send("Runtime.evaluate", {"expression": IMAGE_CHECK, "awaitPromise": True,
                                             "returnByValue": True}, session=s)["result"]["value"]
        height = b.send("Runtime.evaluate", {
            "expression": "document.documentElement.scrollHeight", "returnByValue": True},
            session=s)["result"]["value"]
        b.send("Emulation.setDeviceMetricsOverride",
               {"width": WIDTH, "height": int(height), "deviceScaleFactor": 1, "mobile": False},
               session=s)
        png = b.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True},
                     session=s)["data"]
        shot.write_bytes(base64.b64decode(png))
        return images, console_errors(b.events)
    finally:
        b.close()


def assert_new_figures(images: list[dict[str, Any]], prefixes: tuple[str, ...]) -> None:
    """Each figure whose caption starts with one of ``prefixes`` is in the page, decoded, and
    at least 1600 px wide."""
    for prefix in prefixes:
        found = [i for i in images if i["alt"].startswith(prefix)]
        assert len(found) == 1, (prefix, [i["alt"] for i in images])
        assert found[0]["w"] >= 1600, found[0]


class _Shifted:
    """Truth + 1.5 m (a stand-in estimator, so the test needs no solver)."""

    def __init__(self, name: str, offset: float) -> None:
        self.name, self.offset = name, offset

    def run(self, drive: Any) -> Any:
        from vnav_graph.types import Estimate, Trajectory

        tr = drive.truth
        lla = tr.lla[::10].copy()
        lla[:, 2] += self.offset
        return Estimate(self.name, Trajectory(tr.t[::10], lla, tr.vel_n[::10], tr.q_nb[::10]),
                        frozenset({"alt", "vel_d", "pos_h", "att"}), runtime_s=0.1)


needs_chromium = pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium absent (Debian: apt-get install -y chromium)")


@needs_chromium
def test_checks_catch_a_broken_page(tmp_path: Path) -> None:
    """The probe itself can fail: a truncated PNG and a script error are both reported."""
    page = tmp_path / "broken.html"
    page.write_text('<!DOCTYPE html><html><body><img alt="truncated" '
                    'src="data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAA">'
                    '<script>console.error("planted error"); undefinedFunction();</script>'
                    "</body></html>", encoding="utf-8")
    images, errors = load_report(page, tmp_path / "broken.png", tmp_path)
    assert [i["w"] for i in images] == [0] and images[0]["err"]
    assert any("planted error" in e for e in errors)
    assert any("undefinedFunction" in e for e in errors)


@needs_chromium
def test_report_in_headless_chromium(tmp_path: Path) -> None:
    drive = simulate(shorten_scenario("hill-drive", 60.0), 3)
    results = [RunResult(n, _Shifted(n, off).run(drive), None, 0.1)
               for n, off in (("ekf-rts", 0.5), ("graph-batch", 0.7), ("loop2", 2.0))]
    results.append(RunResult("broken", None, "RuntimeError: planted failure", 0.1))
    summary = summarize(drive, results)
    write_report(tmp_path / "out", summary, results, drive)
    html = tmp_path / "out" / "report.html"
    art = Path(os.environ.get("VNAV_ARTIFACTS") or tmp_path / "artifacts")
    art.mkdir(parents=True, exist_ok=True)
    shot = art / "report_screenshot.png"
    images, errors = load_report(html, shot, tmp_path)
    assert errors == []
    n_png = len(list((tmp_path / "out" / "plots").glob("*.png")))
    assert len(images) == n_png >= 2
    bad = [i for i in images if i["w"] <= 0 or i["err"]]
    assert bad == [], bad
    assert_new_figures(images, ("Horizontal position error", "Heading (yaw) error",
                                "Trajectory map"))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000


@needs_chromium
@pytest.mark.slow
def test_real_log_report_in_headless_chromium(tmp_path: Path, data_dir: Path) -> None:
    """A real log's report (holdout windows, no truth, the drive's own clock and datum)
    loads as cleanly as a simulated one: ``vnav-graph run`` on Loiter_RTL.bin with two fast
    estimators."""
    import sys

    log = data_dir / "erle_pxf_loiter_rtl" / "Loiter_RTL.bin"
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "vnav_graph", "run", str(log), "--estimators",
                           "ekf,loop2", "--out", str(out), "--no-progress"],
                          capture_output=True, text=True, timeout=900)
    # exit 3: loop2's holdout run loses the fixes on this log (height residual above 1 km,
    # "diverged"); the report is written for every estimator either way
    assert proc.returncode in (0, 3), proc.stderr[-2000:]
    assert proc.returncode == 0 or "diverged (loop2" in proc.stderr, proc.stderr[-2000:]
    art = Path(os.environ.get("VNAV_ARTIFACTS") or tmp_path / "artifacts")
    art.mkdir(parents=True, exist_ok=True)
    images, errors = load_report(out / "report.html", art / "report_real_log_screenshot.png",
                                 tmp_path)
    assert errors == []
    n_png = len(list((out / "plots").glob("*.png")))
    assert len(images) == n_png >= 2
    bad = [i for i in images if i["w"] <= 0 or i["err"]]
    assert bad == [], bad
    # no truth: no heading figure (GNSS gives no heading); the holdout run's map and errors
    assert_new_figures(images, ("Horizontal position error", "Trajectory map"))
    assert "withheld" in (out / "report.html").read_text().lower()
