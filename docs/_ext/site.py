"""Build the documentation site: stage the sources, generate the CLI reference, run Sphinx, check the links.

Sphinx reads one source folder, and the site's sources live in three places: the pages in ``docs/``,
the percent-format notebooks in ``notebooks/`` (the tutorials) and the command-line parsers of the four
commands. This script copies the first two into one staging folder (``tutorials/`` for the notebooks),
writes one CLI reference page per command there from its ``argparse`` parser, and runs Sphinx on it
with the configuration of ``docs/conf.py``: every warning is an error, unresolved references included
(nitpicky). A last pass reads every HTML page written and refuses a relative link whose file or
anchor is not in the site (references Sphinx does not resolve itself, such as raw HTML and images).

    python docs/_ext/site.py [--out DIR] [--execute cache|off] [--docs DIR] [--notebooks DIR]

Exit status 0 when the site is built without a warning and every internal link resolves, 1 otherwise.
"""

from __future__ import annotations

import argparse
import importlib
import io
import os
import shutil
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

ROOT = Path(__file__).resolve().parents[2]

#: The commands of the toolkit and the function that builds each one's complete parser
#: (``hil``'s is the bench's, which also lists the vehicle's sub-commands).
COMMANDS = {
    "gnss": "gnss.cli:build_parser",
    "identification": "identification.cli:build_parser",
    "design": "design.cli:build_parser",
    "hil": "hil.bench.cli:build_parser",
}

#: Width of the generated help text, characters (argparse reads it from ``COLUMNS``).
HELP_WIDTH = 100

#: Folders and files of ``docs/`` that are configuration, not pages.
NOT_PAGES = {"conf.py", "_ext", "_templates", "_static", "__pycache__"}

#: Largest HTML page the link check reads, bytes (the largest page today is well under 2 MB).
MAX_PAGE_BYTES = 32 * 1024 * 1024


class SiteError(RuntimeError):
    """The site could not be built, or it was built with a warning or a broken internal link."""


def load_parser(spec: str) -> argparse.ArgumentParser:
    """The parser that ``spec`` (``module:function``) builds."""
    module, _, func = spec.partition(":")
    return getattr(importlib.import_module(module), func)()


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Every sub-command of ``parser`` by name, nested ones as ``"outer inner"`` (aliases once)."""
    found: dict[str, argparse.ArgumentParser] = {}
    seen: set[int] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if id(sub) in seen:
                    continue
                seen.add(id(sub))
                found[name] = sub
                found.update({f"{name} {inner}": p for inner, p in subcommands(sub).items()})
    return found


def _help(parser: argparse.ArgumentParser) -> str:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_WIDTH)
    try:
        return parser.format_help().rstrip()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def cli_page(command: str, spec: str) -> str:
    """The Markdown reference page of ``command``: its help and every sub-command's, as ``--help`` prints them."""
    parser = load_parser(spec)
    subs = subcommands(parser)
    out = io.StringIO()
    out.write(f"# `{command}`\n\n")
    out.write(f"Generated from the command's parser (`{spec}`) when the site is built; "
              f"`{command} SUB-COMMAND --help` prints the same text.\n\n")
    if subs:
        out.write("| sub-command | what it does |\n| --- | --- |\n")
        for name, sub in subs.items():
            anchor = "-".join([command, *name.split()])
            summary = _summary(parser, name).replace("|", "\\|").replace("<", "\\<")   # table cell, no HTML
            out.write(f"| [`{command} {name}`](#{anchor}) | {summary} |\n")
        out.write("\n")
    out.write(f"```text\n{_help(parser)}\n```\n")
    for name, sub in subs.items():
        anchor = "-".join([command, *name.split()])
        out.write(f"\n({anchor})=\n## `{command} {name}`\n\n```text\n{_help(sub)}\n```\n")
    return out.getvalue()


def _summary(parser: argparse.ArgumentParser, name: str) -> str:
    """The one-line help that ``parser`` gives the sub-command ``name`` (outer ones first)."""
    words = name.split()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and words[0] in action.choices:
            if len(words) > 1:
                return _summary(action.choices[words[0]], " ".join(words[1:]))
            for choice in action._choices_actions:
                if choice.dest == words[0]:
                    return " ".join((choice.help or "").split())
    return ""


def _write_if_changed(path: Path, text: str) -> None:
    if path.exists() and path.read_text(encoding="utf-8") == text:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def stage(docs: Path, notebooks: Path, staging: Path) -> None:
    """Lay out the site's sources in ``staging``: the pages of ``docs``, the notebooks as ``tutorials/``,
    the CLI reference as ``cli/COMMAND.md``."""
    if staging.exists():
        shutil.rmtree(staging)
    shutil.copytree(docs, staging, ignore=lambda folder, names: [n for n in names if n in NOT_PAGES])
    tutorials = staging / "tutorials"
    tutorials.mkdir(exist_ok=True)
    found = sorted(notebooks.glob("[0-9]*.py"))
    if not found:
        raise SiteError(f"{notebooks}: expected the percent-format notebooks NN_name.py, found none; "
                        "pass --notebooks with the notebooks' folder")
    for nb in found:
        shutil.copy2(nb, tutorials / nb.name)
    for command, spec in COMMANDS.items():
        _write_if_changed(staging / "cli" / f"{command}.md", cli_page(command, spec))


def sphinx(conf: Path, staging: Path, out: Path, cache: Path, execute: str) -> subprocess.CompletedProcess:
    """Run Sphinx (HTML, every warning an error, nitpicky, a fresh environment so that every page's
    warnings are reported on every build); the notebooks' outputs come from ``cache`` (jupyter-cache)."""
    cmd = [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-n", "-E", "-q",
           "-c", str(conf), "-d", str(cache / "doctrees"),
           "-D", f"nb_execution_mode={execute}",
           "-D", f"nb_execution_cache_path={cache / 'jupyter_cache'}",
           str(staging), str(out)]
    print("+", " ".join(cmd), flush=True)
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    return subprocess.run(cmd, cwd=ROOT, env=env)


class _Links(HTMLParser):
    """Collects the ``id`` / ``name`` anchors of a page and its ``href`` / ``src`` links."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if value is None:
                continue
            if key == "id" or (key == "name" and tag == "a"):
                self.ids.add(value)
            elif key in ("href", "src") and tag not in ("link", "script"):
                self.links.append(value)


def _read_page(path: Path) -> _Links:
    size = path.stat().st_size
    if size > MAX_PAGE_BYTES:
        raise SiteError(f"{path}: expected an HTML page under {MAX_PAGE_BYTES} bytes, found {size}; "
                        "split the page or raise MAX_PAGE_BYTES in docs/_ext/site.py")
    page = _Links()
    page.feed(path.read_text(encoding="utf-8", errors="replace"))
    return page


def broken_links(out: Path) -> list[str]:
    """Every relative link of the HTML site in ``out`` whose file or anchor is missing, one line each."""
    pages = {p.resolve(): _read_page(p) for p in sorted(out.rglob("*.html"))}
    broken = []
    for path, page in pages.items():
        for link in page.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith(("mailto:", "data:")):
                continue
            target = (path.parent / unquote(parts.path)).resolve() if parts.path else path
            if target.is_dir():
                target = target / "index.html"
            where = path.relative_to(out.resolve())
            if not target.is_file() or not target.is_relative_to(out.resolve()):
                broken.append(f"{where}: link {link!r}: no such file in the site")
            elif parts.fragment and target.suffix == ".html":
                ids = pages[target].ids if target in pages else _read_page(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{where}: link {link!r}: no anchor {parts.fragment!r} in {target.name}")
    return broken


def _clear_site(out: Path) -> None:
    """Remove the previous site in ``out`` (pages of removed modules or documents would stay, and links to
    them pass); refuse a folder that is not one."""
    if not out.exists():
        return
    if not (out / ".buildinfo").is_file():
        raise SiteError(f"{out}: expected a folder that holds a site built before (with its .buildinfo) or "
                        "none, found another folder; pass --out with a new folder")
    shutil.rmtree(out)


def build(out: Path, execute: str = "cache", docs: Path | None = None, notebooks: Path | None = None,
          work: Path | None = None) -> float:
    """Build the site into ``out``; returns the seconds it took. Raises :class:`SiteError` on any warning
    or broken internal link."""
    docs = docs or ROOT / "docs"
    notebooks = notebooks or ROOT / "notebooks"
    work = work or out.parent / f"{out.name}-work"
    t0 = time.monotonic()
    _clear_site(out)
    stage(docs, notebooks, work / "src")
    done = sphinx(docs, work / "src", out, work, execute)
    if done.returncode != 0:
        raise SiteError(f"sphinx-build on {docs} failed (exit {done.returncode}): every warning above is an "
                        "error; fix the page, docstring or reference it names")
    broken = broken_links(out)
    if broken:
        raise SiteError("\n".join(broken) + f"\n{len(broken)} broken internal link(s) in {out}: fix the link in "
                        "the page that holds it")
    return time.monotonic() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python docs/_ext/site.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=ROOT / "out" / "docs", help="the HTML site's folder")
    p.add_argument("--execute", choices=("cache", "off"), default="cache",
                   help="cache: run the notebooks and keep their outputs under OUT-work (default); off: render "
                        "them without outputs")
    p.add_argument("--docs", type=Path, default=ROOT / "docs", help="the pages and conf.py")
    p.add_argument("--notebooks", type=Path, default=ROOT / "notebooks", help="the percent-format notebooks")
    args = p.parse_args(argv)
    try:
        seconds = build(args.out.resolve(), args.execute, args.docs.resolve(), args.notebooks.resolve())
    except (SiteError, OSError) as exc:
        print(f"docs: error: {exc}", file=sys.stderr)
        return 1
    print(f"docs: built {args.out} in {seconds:.0f} s (notebooks: {args.execute})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
