"""Reports as pages read in a browser: a subset of Markdown, tables and provenance rendered with Jinja2.

Every report of the toolkit is written as ``report.md`` (kept for grep) and as ``index.html`` (the page)
from the same lines: :func:`blocks` turns the Markdown the reports write (headings, pipe tables,
paragraphs, lists, fenced code, images, inline code) into blocks, :func:`write_page` renders them
through ``templates/report.html.j2`` with a table of contents and the run's provenance
(:func:`provenance`: date, toolkit version, git commit, tractor, options, seeds, sha256 of the
controller files). Cells that say pass or fail (``ok``, ``yes``, ``met``; ``NO``, ``FAILED``,
``missed``...) are marked in colour and keep their text.

The module sits in :mod:`hil.commissioning` so that the bench and the commissioning from logs both
import it (the commissioning imports nothing of the bench).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import html as _html
import json
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from identification.outputs import atomic_write
from autosteer.version import toolkit_version

__all__ = ["Table", "Cell", "blocks", "provenance", "render_page", "write_page", "file_sha256"]

#: Largest controller file hashed for the provenance, bytes (a controller file is a few kB).
HASH_MAX_BYTES = 64 * 2 ** 20
#: Seconds allowed to each ``git`` call of the provenance.
GIT_TIMEOUT_S = 10.0

_PASS = re.compile(r"^(ok|yes|met|passed|pass|accepted|stable on every model)\b", re.I)
_FAIL = re.compile(r"^(no|not met|missed|fail|failed|not stable|refused)\b", re.I)


@dataclass(frozen=True)
class Cell:
    """One table cell: its text, ``status`` (``"pass"``, ``"fail"`` or ``""``), columns spanned, and whether it
    is numeric (right-aligned)."""

    text: str
    status: str = ""
    span: int = 1
    numeric: bool = False

    @property
    def css(self) -> str:
        """The cell's classes: its status and ``num`` when numeric."""
        return " ".join(x for x in (self.status, "num" if self.numeric else "") if x)


@dataclass(frozen=True)
class Table:
    """A table block: header rows and body rows of :class:`Cell`, and an optional caption."""

    header: Sequence[Sequence[Cell]]
    rows: Sequence[Sequence[Cell]]
    caption: str = ""
    kind: str = field(default="table", init=False)


@dataclass(frozen=True)
class _Block:
    kind: str
    text: str = ""
    items: tuple = ()
    level: int = 0
    anchor: str = ""


def status_of(text: str) -> str:
    """``"pass"``, ``"fail"`` or ``""`` for a cell's text (its first words)."""
    t = text.strip()
    if _FAIL.match(t):
        return "fail"
    if _PASS.match(t):
        return "pass"
    return ""


def inline(text: str) -> str:
    """HTML of one line of Markdown text: escaped, ```code``` as ``<code>``, ``**strong**`` as ``<strong>``."""
    out = _html.escape(text, quote=False)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out)


def _split_row(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _md_table(lines: list[str]) -> Table:
    rows = [_split_row(line) for line in lines]
    sep = next((i for i, r in enumerate(rows) if r and all(set(c) <= set("-: ") and c for c in r)), None)
    right = [c.endswith(":") for c in rows[sep]] if sep is not None else []
    head = rows[:sep] if sep is not None else []
    body = rows[sep + 1:] if sep is not None else rows

    def cells(r: list[str], header: bool) -> list[Cell]:
        return [Cell(c, "" if header else status_of(c), 1, j < len(right) and right[j]) for j, c in enumerate(r)]
    return Table([cells(r, True) for r in head], [cells(r, False) for r in body])


def _anchor(text: str, used: set[str]) -> str:
    base = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"
    name, n = base, 2
    while name in used:
        name, n = f"{base}-{n}", n + 1
    used.add(name)
    return name


def blocks(lines: Iterable[str | Table]) -> list:
    """Blocks of the page from Markdown lines (a line may hold several, split at newlines) and :class:`Table` s.

    Handled: ``##``/``###`` headings (a ``#`` heading is the page's title, given apart, and is
    dropped), pipe tables (the separator row sets right alignment), fenced code, ``- `` lists,
    ``![alt](file)`` images, and paragraphs (consecutive lines joined).
    """
    flat: list[str | Table] = []
    for x in lines:
        flat.extend([x] if isinstance(x, Table) else str(x).split("\n"))
    out: list = []
    used: set[str] = set()
    para: list[str] = []
    i = 0

    def flush() -> None:
        if para:
            out.append(_Block("p", " ".join(inline(p) for p in para)))
            para.clear()
    while i < len(flat):
        line = flat[i]
        if isinstance(line, Table):
            flush()
            out.append(line)
            i += 1
            continue
        s = line.rstrip()
        if s.startswith("```"):
            flush()
            j = i + 1
            while j < len(flat) and not (isinstance(flat[j], str) and flat[j].startswith("```")):
                j += 1
            out.append(_Block("pre", "\n".join(str(x) for x in flat[i + 1:j])))
            i = j + 1
            continue
        if s.startswith("|"):
            flush()
            j = i
            while j < len(flat) and isinstance(flat[j], str) and flat[j].startswith("|"):
                j += 1
            out.append(_md_table([str(x) for x in flat[i:j]]))
            i = j
            continue
        m = re.match(r"^(#{1,3}) (.*)$", s)
        img = re.match(r"^!\[([^\]]*)\]\(([^)\s]+)\)$", s.strip())
        if m:
            flush()
            level = len(m.group(1))
            if level > 1:
                out.append(_Block("h", inline(m.group(2)), level=level, anchor=_anchor(m.group(2), used)))
        elif img:
            flush()
            out.append(_Block("img", inline(img.group(1)), items=(img.group(2),)))
        elif s.startswith("- "):
            flush()
            items = []
            while i < len(flat) and isinstance(flat[i], str) and flat[i].startswith("- "):
                items.append(inline(flat[i][2:]))
                i += 1
            out.append(_Block("ul", items=tuple(items)))
            continue
        elif s.strip():
            para.append(s.strip())
        else:
            flush()
        i += 1
    flush()
    return out


def git_commit(where: Path | None = None) -> str:
    """The commit of the checkout holding the toolkit's code (``+ uncommitted changes`` when the tracked
    files differ from it), or ``"unknown"`` when the code is not in a git checkout (an installed wheel)."""
    root = (where or Path(__file__).resolve().parents[2])
    if not (root / ".git").exists():
        return "unknown"
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=GIT_TIMEOUT_S)
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=GIT_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    return head.stdout.strip() + (" + uncommitted changes" if dirty.returncode == 0 and dirty.stdout.strip() else "")


def file_sha256(path: str | Path) -> str:
    """sha256 of a file (hex), or why it has none (missing, larger than :data:`HASH_MAX_BYTES`)."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > HASH_MAX_BYTES:
            return f"not hashed: {size} bytes > {HASH_MAX_BYTES}"
        h = hashlib.sha256()
        with open(p, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        return h.hexdigest()
    except OSError as exc:
        return f"not hashed: {exc.strerror or exc}"


def _value(v: object) -> str:
    if isinstance(v, (list, tuple)):
        return ", ".join(_value(x) for x in v) or "none"
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True, default=str)
    return "none" if v is None else str(v)


def provenance(tractor: str | None = None, options: Mapping[str, object] | None = None,
               seeds: Sequence[int] | None = None, files: Mapping[str, str] | None = None,
               when: _dt.datetime | None = None) -> list[tuple[str, str]]:
    """What made a report, as (label, value) rows.

    Parameters
    ----------
    tractor
        The tractor's name (None: ``"not named"``).
    options
        The options of the command (each shown as ``name = value``).
    seeds
        The random seeds of the runs.
    files
        Controller files: path -> sha256 (hex); a path without one is hashed here.
    when
        The report's time (default: now, UTC).
    """
    now = (when or _dt.datetime.now(_dt.timezone.utc)).astimezone(_dt.timezone.utc)
    rows = [("date (UTC)", now.strftime("%Y-%m-%d %H:%M:%S")), ("toolkit version", toolkit_version()),
            ("git commit", git_commit()), ("tractor", tractor or "not named"),
            ("seeds", _value(list(seeds)) if seeds is not None else "none")]
    rows += [(f"option {k}", _value(v)) for k, v in (options or {}).items()]
    for path, digest in (files or {}).items():
        rows.append((f"sha256 of {path}", digest or file_sha256(path)))
    if not files:
        rows.append(("controller files", "none"))
    return rows


def _environment():
    import jinja2
    from markupsafe import Markup
    env = jinja2.Environment(loader=jinja2.PackageLoader("hil.commissioning", "templates"),
                              autoescape=jinja2.select_autoescape(["html", "j2"]), undefined=jinja2.StrictUndefined,
                              trim_blocks=True, lstrip_blocks=True)
    env.filters["code"] = lambda text: Markup(inline(str(text)))
    return env


def render_page(title: str, lines: Iterable[str | Table], prov: Sequence[tuple[str, str]] = (),
                summary: str = "") -> str:
    """The page (HTML text) of a report: title, summary line, table of contents, blocks, provenance."""
    from markupsafe import Markup
    bs = [b if isinstance(b, Table) or b.kind in ("pre", "img") and not b.text
          else _Block(b.kind, b.text if b.kind == "pre" else Markup(b.text),
                      b.items if b.kind == "img" else tuple(Markup(x) for x in b.items), b.level, b.anchor)
          for b in blocks(lines)]
    toc = [b for b in bs if getattr(b, "kind", "") == "h"]
    return _environment().get_template("report.html.j2").render(
        title=title, summary=Markup(inline(summary)) if summary else "", blocks=bs, toc=toc, provenance=list(prov))


def write_page(path: str | Path, title: str, lines: Iterable[str | Table], prov: Sequence[tuple[str, str]] = (),
               summary: str = "") -> Path:
    """Write :func:`render_page` to ``path`` (whole or not at all); returns the path."""
    path = Path(path)
    text = render_page(title, lines, prov, summary)
    with atomic_write(path, "w") as fh:
        fh.write(text)
    return path
