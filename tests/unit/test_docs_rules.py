"""Rules on the repository's text, read from the files:

- no development-history wording in ``vnav_graph/``, ``tests/``, ``docs/``, ``benchmarks/``,
  ``examples/`` or ``README.md`` (a dated diary belongs in git history, not in the product);
- every relative link of ``README.md``, ``CHANGELOG.md`` and ``docs/*.md`` resolves (file, and
  heading when the link has an anchor), and every ``.py`` path those pages name exists;
- the README's Layout section names every top-level module and package of ``vnav_graph/``;
- the README's set-up commands are the ones ``.ci/run`` runs.

Each finder is also run on a small bad sample, so a finder that sees nothing fails.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
TEXT_SUFFIXES = {".py", ".md", ".toml", ".txt", ".cfg", ".ini", ".json", ".csv", ".html"}
SCANNED = ("vnav_graph", "tests", "docs", "benchmarks", "examples")

# history wording: the word "session" after an ordinal or "this", or before a number; "stop"
# or "issue" before a number; "brief" after "the". A browser's session (the DevTools
# protocol's "sessionId") does not match.
_ORDINAL = r"(?:first|second|third|fourth|fifth|last|previous|next|this|that|\d+(?:st|nd|rd|th))"
HISTORY = re.compile(
    r"\bsessions?\s+#?\d+|\b" + _ORDINAL + r"\s+session\b|\bstops?\s+#?\d+\b"
    r"|\bissues?\s+#?\d+|\bthe\s+brief\b", re.IGNORECASE)


def _text_files(root: Path) -> list[Path]:
    """The tracked text files (every file when ``root`` is not a git checkout)."""
    try:
        names = subprocess.run(["git", "ls-files", *SCANNED, "README.md"], cwd=root, check=True,
                               capture_output=True, text=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        names = None
    if names:
        return [root / n for n in names if Path(n).suffix in TEXT_SUFFIXES]
    files = []
    for name in SCANNED:
        files += [p for p in (root / name).rglob("*")
                  if p.is_file() and p.suffix in TEXT_SUFFIXES and "__pycache__" not in p.parts]
    readme = root / "README.md"
    return files + ([readme] if readme.exists() else [])


def history_wording(root: Path) -> list[str]:
    out = []
    for path in _text_files(root):
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            m = HISTORY.search(line)
            if m:
                out.append(f"{path.relative_to(root).as_posix()}:{n}: {m.group(0)!r}")
    return out


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    s = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return s.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", page.read_text(), re.M)}


LINK = re.compile(r"\]\(([^)\s]+)\)")
PY_PATH = re.compile(r"`([\w./]+\.py)\b")


def broken_links(root: Path, pages: list[Path]) -> list[str]:
    tracked = [p.relative_to(root).as_posix() for p in root.rglob("*.py")
               if ".venv" not in p.parts]
    out = []
    for page in pages:
        text = page.read_text()
        where = page.relative_to(root).as_posix()
        for target in LINK.findall(text):
            if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            dest = (page.parent / file) if file else page
            if not dest.exists():
                out.append(f"{where}: link {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                out.append(f"{where}: link {target} (no such heading)")
        for name in PY_PATH.findall(text):
            if not any(t == name or t.endswith("/" + name) for t in tracked):
                out.append(f"{where}: `{name}` (no such file)")
    return out


def _doc_pages(root: Path) -> list[Path]:
    pages = [root / "README.md", root / "CHANGELOG.md", *sorted((root / "docs").glob("*.md"))]
    return [p for p in pages if p.exists()]


def layout_gaps(root: Path) -> list[str]:
    """Top-level modules and packages of vnav_graph/ that the README's Layout section omits."""
    readme = (root / "README.md").read_text()
    m = re.search(r"^## Layout\n(.*?)(?=^## |\Z)", readme, re.M | re.S)
    if m is None:
        return ["README.md has no '## Layout' section"]
    words = set(re.findall(r"[\w.]+", m.group(1)))
    out = []
    for p in sorted((root / "vnav_graph").iterdir()):
        if p.name.startswith(("_", ".")) or p.suffix not in (".py", ""):
            continue
        if p.is_dir() and not (p / "__init__.py").exists() and p.name != "scenarios":
            continue
        if p.name not in words and p.stem not in words:
            out.append(p.name)
    return out


def readme_commands(root: Path) -> list[str]:
    """The README's ```bash blocks that ``.ci/run`` does not run verbatim (continuation lines
    joined, runs of blanks collapsed)."""
    flat = " ".join(re.sub(r"\\\n", " ", (root / ".ci" / "run").read_text()).split())
    blocks = re.findall(r"```bash\n(.*?)```", (root / "README.md").read_text(), re.S)
    return [b.strip() for b in blocks if " ".join(b.split()) not in flat] + (
        [] if blocks else ["no ```bash block in README.md"])


def test_readme_commands_are_the_ci_commands():
    assert not readme_commands(REPO), f"README commands not in .ci/run: {readme_commands(REPO)}"


def test_no_development_history_wording():
    found = history_wording(REPO)
    assert not found, "history wording (say what the code does; history goes in git):\n" + \
        "\n".join(found)


def test_doc_links_and_module_paths_resolve():
    found = broken_links(REPO, _doc_pages(REPO))
    assert not found, "\n".join(found)


def test_readme_layout_names_every_top_level_module():
    assert not layout_gaps(REPO), f"not in the README's Layout: {layout_gaps(REPO)}"


def test_the_finders_see_bad_text(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "vnav_graph" / "pkg").mkdir(parents=True)
    (tmp_path / "vnav_graph" / "pkg" / "__init__.py").write_text("")
    (tmp_path / "vnav_graph" / "mod.py").write_text("x = 1  # the 2nd " + "session's value\n")
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "t.py").write_text('msg["sessionId"] = s  # a browser session\n')
    page = tmp_path / "docs" / "a.md"
    page.write_text("# Top\nSee [b](b.md), [top](#top), [gone](#nowhere) and `graph/init.py`.\n"
                    "Fixed in " + "st" + "op 25,\nas the " + "br" + "ief said.\n")
    (tmp_path / "README.md").write_text("# R\n## Layout\n```\nvnav_graph/\n  mod.py\n```\n")
    assert sorted(h.split(":")[0] for h in history_wording(tmp_path)) == [
        "docs/a.md", "docs/a.md", "vnav_graph/mod.py"]
    assert broken_links(tmp_path, [page]) == [
        "docs/a.md: link b.md (no such file)", "docs/a.md: link #nowhere (no such heading)",
        "docs/a.md: `graph/init.py` (no such file)"]
    assert layout_gaps(tmp_path) == ["pkg"]
    (tmp_path / ".ci").mkdir()
    (tmp_path / ".ci" / "run").write_text("time (pip install . \\\n     && vnav-graph run)\n")
    (tmp_path / "README.md").write_text("```bash\npip install . && vnav-graph run\n```\n"
                                        "```bash\npip install -e .\n```\n")
    assert readme_commands(tmp_path) == ["pip install -e ."]
