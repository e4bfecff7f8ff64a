"""The user documentation and the product's docstrings and comments carry no development history.

Development history (work sessions, issue or round numbers, who did what, dates, commit hashes) belongs in
git; machine paths (``/work/``, ``/tmp/``, ``/home/``) are meaningless to a user. Checked here:

- ``README.md``, every Markdown file under ``docs/`` and ``CHANGELOG.md`` (a date is allowed only in a
  CHANGELOG version heading such as ``## 1.2.0 (2027-01-15)``); a commit hash is allowed where it pins an
  upstream repository's source (the line names it as a backticked ``owner/name``) and a hexadecimal digest
  where the line says ``sha256``;
- the docstrings and comments of the product packages (``gnss``, ``identification``, ``design``,
  ``hil``); commit hashes are not checked there, as they pin upstream sources.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("autosteer", "gnss", "identification", "design", "hil")

HISTORY = re.compile(r"(?i:\bsessions?\s+\d+|\bissues?\s+#?\d+|\bround\s+\d+)|(?i:\bengineer)\s+[A-Z]\b"
                     r"|/work/|/tmp/|/home/")
DATE = re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b")
COMMIT = re.compile(r"\b(?!ed25519\b)(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
VERSION_HEADING = re.compile(r"^#+ .*\d+\.\d+")
OURS = {"autosteer", "gnss", "identification", "design", "hil", "docs", "tests", "notebooks", "benchmarks", "models", "out"}
UPSTREAM = re.compile(r"`([\w.-]+)/[\w.-]+`")


def _markdown_files() -> list[Path]:
    # build output and templates live in folders whose names start with "_" or "."
    pages = [p for p in ROOT.glob("docs/**/*.md")
             if not any(part.startswith(("_", ".")) for part in p.relative_to(ROOT / "docs").parts)]
    return [ROOT / "README.md"] + sorted(pages) + [ROOT / "CHANGELOG.md"]


def _cites_upstream(line: str) -> bool:
    return any(m.group(1) not in OURS for m in UPSTREAM.finditer(line))


def markdown_findings(path: Path, text: str) -> list[str]:
    """Lines of a Markdown text that carry development history or a machine path.

    Parameters
    ----------
    path : Path
        The file the text came from (named in each finding).
    text : str
        Its content.

    Returns
    -------
    list of str
        One ``file:line: match`` per finding.
    """
    found = []
    changelog = path.name == "CHANGELOG.md"
    for number, line in enumerate(text.splitlines(), 1):
        hits = [m.group(0) for m in HISTORY.finditer(line)]
        if not (changelog and VERSION_HEADING.match(line)):
            hits += [m.group(0) for m in DATE.finditer(line)]
        if "sha256" not in line and not _cites_upstream(line):
            hits += [m.group(0) for m in COMMIT.finditer(line)]
        found += [f"{path.relative_to(ROOT)}:{number}: {hit!r}" for hit in hits]
    return found


def python_findings(path: Path, source: str) -> list[str]:
    """Docstrings and comments of a Python source that carry development history or a machine path.

    Parameters
    ----------
    path : Path
        The file the source came from (named in each finding).
    source : str
        Its content.

    Returns
    -------
    list of str
        One ``file:line: match`` per finding.
    """
    texts = [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(source).readline)
             if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                texts.append((node.body[0].lineno, doc))
    found = []
    for number, text in texts:
        hits = [m.group(0) for m in HISTORY.finditer(text)] + [m.group(0) for m in DATE.finditer(text)]
        found += [f"{path.relative_to(ROOT)}:{number}: {hit!r}" for hit in hits]
    return found


@pytest.mark.parametrize("path", _markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_markdown_has_no_history(path: Path) -> None:
    found = markdown_findings(path, path.read_text(encoding="utf-8"))
    assert not found, ("development history or machine paths in the docs (state today's facts, "
                       "put how they were reached in git): " + "; ".join(found))


def _python_params():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield pytest.param(path, id=str(path.relative_to(ROOT)))


@pytest.mark.parametrize("path", list(_python_params()))
def test_product_docstrings_and_comments_have_no_history(path: Path) -> None:
    found = python_findings(path, path.read_text(encoding="utf-8"))
    assert not found, ("development history or machine paths in docstrings or comments (say what the code "
                       "does and why): " + "; ".join(found))


@pytest.mark.parametrize("text, expected", [
    ("# Results (issue 16)", ["'issue 16'"]),
    ("Issues #18 and #19", ["'Issues #18'"]),
    ("Measured in session 8 by engineer F.", ["'session 8'", "'engineer F'"]),
    ("round 2 of the search", ["'round 2'"]),
    ("outputs in /tmp/F2/ and /work/c11/x.json", ["'/tmp/'", "'/work/'"]),
    ("measured at commit `0bb83de` on 2026-12-01", ["'2026-12-01'", "'0bb83de'"]),
    ("source `owner/repo` `src/a.ino` (afb2fb6)", []),
    ("controller (sha256 b306e8ab94568d2d...)", []),
    ("up to 8 rounds; an engineer can; 2.85 m; seed 1997", []),
])
def test_markdown_findings_patterns(text: str, expected: list[str]) -> None:
    found = markdown_findings(ROOT / "docs" / "x.md", text)
    assert [f.split(": ", 1)[1] for f in found] == expected
