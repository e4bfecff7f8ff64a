"""The toolkit as an installable package: dependency ranges, licence, version, and a wheel that runs.

The slow test builds the wheel without build isolation (no download), installs it with ``--no-deps``
into a new virtual environment that sees the project environment's packages through a ``.pth`` file
(the dependencies are not downloaded again), and runs the commands from outside the checkout.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from design.cli import main as design_main
from gnss.cli import main as gnss_main
from hil.cli import main as hil_main
from identification.cli import main as identification_main

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _locked() -> dict[str, str]:
    out = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if "==" in line and not line.startswith("#"):
            name, version = line.split("==", 1)
            out[name.strip().lower().replace("_", "-")] = version.strip()
    return out


def test_dependencies_are_ranges_that_hold_the_locked_versions():
    locked = _locked()
    reqs = [Requirement(r) for r in PYPROJECT["dependencies"]
            + [r for extra in PYPROJECT["optional-dependencies"].values() for r in extra]]
    pinned = [str(r) for r in reqs if any(s.operator in ("==", "===") for s in r.specifier)]
    assert not pinned, f"exact pins make the toolkit uninstallable beside other packages: {pinned}"
    for r in reqs:
        name = r.name.lower().replace("_", "-")
        if name in locked:
            assert r.specifier.contains(locked[name]), f"{r} excludes the locked {name}=={locked[name]}"
    assert any(r.name.lower() == "jinja2" for r in reqs[:len(PYPROJECT["dependencies"])])


def test_the_declared_licence_has_its_file():
    assert PYPROJECT["license"] == {"text": "MIT"}
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Copyright (c) the tractor-autosteer authors" in text


VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


@pytest.mark.parametrize("name, main", [("design", design_main), ("identification", identification_main),
                                        ("gnss", gnss_main)])
def test_every_command_prints_the_version_of_pyproject(name, main):
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and out.getvalue() == f"{name} {VERSION}\n"
    assert metadata.version("tractor-autosteer") == VERSION


def test_hil_prints_the_version_of_pyproject(capsys):
    assert hil_main(["--version"]) == 0
    assert capsys.readouterr().out == f"hil {VERSION}\n"


def _copy_sources(dest: Path) -> Path:
    """The files a wheel is built from, copied so that the build leaves nothing in the checkout."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    dest.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, dest / name)
    for pkg in ("autosteer", "gnss", "identification", "design", "hil"):
        shutil.copytree(ROOT / pkg, dest / pkg, ignore=skip)
    return dest


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_the_wheel_installs_and_runs_outside_the_checkout(tmp_path):
    src = _copy_sources((tmp_path / "src"))
    dist, env_dir, work = tmp_path / "dist", tmp_path / "venv", tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]

    def run(cmd: list[str], cwd: Path = work) -> str:
        done = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=240)
        assert done.returncode == 0, f"{cmd}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        return done.stdout

    run([*pip, "wheel", "--quiet", "--no-deps", "--no-build-isolation", "--no-index", "-w", dist, "."], cwd=src)
    wheel, = dist.glob("tractor_autosteer-*.whl")
    run([sys.executable, "-m", "venv", "--without-pip", env_dir])
    py = env_dir / "bin" / "python"
    site = Path(run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).strip())
    project_site = Path(run([sys.executable, "-c",
                             "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).strip())
    # The project environment's packages, after the new environment's own: a plain path line, so that the
    # project's editable-install hook (a .pth file there) is not run and the toolkit comes from the wheel.
    (site / "project-environment.pth").write_text(f"{project_site}\n")
    run([*pip, "--python", py, "install", "--quiet", "--no-deps", "--no-index", wheel])

    bin_ = env_dir / "bin"
    assert run([bin_ / "hil", "--version"]) == f"hil {VERSION}\n"
    assert "usage: design" in run([bin_ / "design", "--help"])
    gains = run([bin_ / "design", "kinematic", "--speeds", "1.79"])
    assert "K_y" in gains and "1.79" in gains
    where = run([py, "-c", "import hil, design, gnss, identification, importlib.metadata as m; "
                 "print(hil.__file__, design.__file__, gnss.__file__, identification.__file__); "
                 "print(m.version('tractor-autosteer'))"]).split()
    assert all(Path(f).is_relative_to(site) for f in where[:4]), f"not from the wheel: {where[:4]}"
    assert where[4] == VERSION
    # The report page's template is package data, and outside a checkout the commit is unknown.
    page = run([py, "-c", "from hil.commissioning.html import provenance, render_page; "
                "print(render_page('t', ['## a', '| x |', '|---|', '| ok |'], provenance()))"])
    assert '<td class="pass">ok</td>' in page and "<td>git commit</td><td>unknown</td>" in page
