"""The documentation site (``python3 tasks.py docs``) builds without a warning, holds its API and CLI
reference, and a broken reference or link fails its build.

The suite builds with the notebooks rendered but not run (``--execute off``): they run in their own tests
(``@pytest.mark.notebook``) and take minutes; ``tasks.py docs`` runs them, cached.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from autosteer.cli import arguments

ROOT = Path(__file__).resolve().parents[1]
SITE_SCRIPT = ROOT / "docs" / "_ext" / "site.py"

_spec = importlib.util.spec_from_file_location("docs_site", SITE_SCRIPT)
site = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(site)

#: Modules whose API page must be there, with one object each page must document.
KEY_OBJECTS = {
    "gnss.nmea": "gnss.nmea.nmea_checksum",
    "gnss.guidance": "gnss.guidance.ABLine",
    "identification.okid": "identification.okid.OKID",
    "identification.model": "identification.model.Model",
    "design.laws.linear": "design.laws.linear.LinearController",
    "design.synthesis.recipes": "design.synthesis.recipes.design_robust_controller",
    "hil.vehicle.loop": "hil.vehicle.loop.VehicleLoop",
    "hil.truth.simulator": "hil.truth.simulator.TractorSimulator",
}


def _build(out: Path, *args: str) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, str(SITE_SCRIPT), "--execute", "off", "--out", str(out), *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    return done, time.monotonic() - t0


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("docs") / "site"
    done, seconds = _build(out)
    print(f"documentation site built in {seconds:.0f} s")
    assert done.returncode == 0, f"the site's build failed:\n{done.stdout[-4000:]}\n{done.stderr[-8000:]}"
    assert "WARNING" not in done.stdout + done.stderr and "ERROR" not in done.stdout + done.stderr, done.stderr[-8000:]
    return out


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_site_has_its_sections_and_the_rendered_notebooks(built):
    index = (built / "index.html").read_text(encoding="utf-8")
    for caption in ("Tutorials", "How-to guides", "Reference", "Explanation"):
        assert caption in index
    for nb in sorted((ROOT / "notebooks").glob("[0-9]*.py")):
        page = built / "tutorials" / f"{nb.stem}.html"
        assert page.stat().st_size > 5000, page
        assert f"tutorials/{nb.stem}.html" in index
    for protocol in sorted((ROOT / "docs").glob("*_protocol.md")):
        assert (built / f"{protocol.stem}.html").exists()
        assert f"{protocol.stem}.html" in index


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_every_page_has_one_place_in_the_navigation(built):
    """No page is listed by two tables of contents (a glob in one section once took in another's pages).

    Read from the navigation every page shows: the sidebar of a page without a table of contents of its own lists
    each entry of the index's tables once per table that includes it (the page itself as "#", so not counted)."""
    page = (built / "bridge_protocol.html").read_text(encoding="utf-8")
    places = Counter(re.findall(r'<li class="toctree-l1[^"]*"><a class="reference internal" href="([^"#]+)"', page))
    assert places["isobus_protocol.html"] == 1 and places["tutorials/01_identification.html"] == 1, places
    assert len(places) > 20, places
    twice = sorted(doc for doc, n in places.items() if n > 1)
    assert not twice, twice


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("module", sorted(KEY_OBJECTS))
def test_the_api_reference_documents_the_key_modules(built, module):
    page = (built / "api" / "generated" / f"{module}.html").read_text(encoding="utf-8")
    assert f'id="{KEY_OBJECTS[module]}"' in page


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("command", sorted(site.COMMANDS))
def test_the_cli_reference_lists_every_subcommand(built, command):
    page = (built / "cli" / f"{command}.html").read_text(encoding="utf-8")
    subs = site.subcommands(site.load_parser(site.COMMANDS[command]))
    assert len(subs) >= 3
    for name, parser in subs.items():
        assert f'id="{"-".join([command, *name.split()])}"' in page, name
        for action in arguments(parser):   # each option by its name (old spellings are hidden from the help)
            if action.option_strings and action.help != argparse.SUPPRESS:
                assert action.option_strings[0] in page, f"{command} {name} {action.option_strings[0]}"


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_broken_reference_or_link_fails_the_build(tmp_path):
    """In a copy of docs/ (the API reference cut to one module, for time), a link to a page that does not
    exist and a reference to a function that does not exist each fail the build, and nothing else does."""
    docs = tmp_path / "docs"
    shutil.copytree(ROOT / "docs", docs, ignore=shutil.ignore_patterns("__pycache__"))
    api = (docs / "api" / "modules.md").read_text(encoding="utf-8")
    cut = api.replace("   gnss\n   identification\n   design\n   hil\n", "   gnss.errors\n")
    assert cut != api, "docs/api/modules.md no longer lists the four packages as this test expects"
    (docs / "api" / "modules.md").write_text(cut, encoding="utf-8")
    index = docs / "index.md"
    index.write_text(index.read_text(encoding="utf-8")
                     + "\nSee [the gone page](no_such_page.md) and {py:func}`gnss.errors.no_such_function`.\n",
                     encoding="utf-8")
    done, _ = _build(tmp_path / "site", "--docs", str(docs))
    assert done.returncode != 0
    warnings = [line for line in done.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert any("index.md" in w and "no_such_page" in w for w in warnings), done.stderr[-4000:]
    assert any("index.md" in w and "gnss.errors.no_such_function" in w for w in warnings), done.stderr[-4000:]
    assert len(warnings) == 2, "\n".join(warnings)
    assert "docs: error: sphinx-build" in done.stderr


def test_the_link_check_refuses_a_missing_file_or_anchor(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "index.html").write_text(
        '<a href="sub/page.html#there">ok</a> <a href="sub/page.html#nowhere">anchor</a> '
        '<img src="missing.png"> <a href="https://example.org/x">outside</a> <a href="#top">self</a>'
        '<p id="top"></p>', encoding="utf-8")
    (tmp_path / "sub" / "page.html").write_text('<h1 id="there">x</h1><a href="../index.html">up</a>',
                                                encoding="utf-8")
    broken = site.broken_links(tmp_path)
    assert len(broken) == 2, broken
    assert "index.html: link 'sub/page.html#nowhere': no anchor 'nowhere' in page.html" in broken
    assert "index.html: link 'missing.png': no such file in the site" in broken
