"""The architecture contracts (.importlinter) hold, and the README's map of the code names them.

A wrong import (the tractor's loop reaching into the simulator, the truth importing a device, a
cycle between design modules) fails here, so it fails CI.
"""

from __future__ import annotations

import configparser
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / ".importlinter"


def test_import_contracts_are_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(lint), "--config", str(CONFIG), "--no-cache"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "BROKEN" not in done.stdout and "KEPT" in done.stdout


def test_every_hil_sub_package_has_a_contract_and_a_line_in_the_readme_map():
    cfg = configparser.ConfigParser()
    cfg.read(CONFIG)
    sources = {m.strip() for sec in cfg.sections() if sec.startswith("importlinter:contract:")
               for m in cfg[sec].get("source_modules", "").split()}
    subs = sorted(p.parent.name for p in (ROOT / "hil").glob("*/__init__.py"))
    assert subs == ["bench", "commissioning", "devices", "links", "truth", "vehicle"]
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Map of the code", 1)[1].split("\n## ", 1)[0]
    for sub in subs:
        assert re.search(rf"^\| `hil/{sub}/` \|", section, re.M), f"README map has no line for hil/{sub}/"
    for sub in ("truth", "links", "vehicle", "devices", "commissioning", "bench.runs", "bench.fields",
                "bench.benches", "bench.commissioning"):
        assert f"hil.{sub}" in sources, f"no contract constrains hil.{sub}"


def test_every_package_has_an_acyclic_contract_and_no_import_is_ignored():
    cfg = configparser.ConfigParser()
    cfg.read(CONFIG)
    contracts = [cfg[sec] for sec in cfg.sections() if sec.startswith("importlinter:contract:")]
    acyclic = {m.strip() for c in contracts if c.get("type") == "acyclic_siblings" for m in c["ancestors"].split()}
    roots = {m.strip() for m in cfg["importlinter"]["root_packages"].split()}
    assert roots == {"autosteer", "gnss", "identification", "design", "hil"} and roots <= acyclic, acyclic
    assert not [c.name for c in contracts if "ignore_imports" in c], "an import contract ignores imports"


def test_no_module_of_design_or_the_bench_stands_outside_a_room():
    """design and the bench keep their modules in rooms (design: core, laws, mpc, files, synthesis, export,
    commands; the bench: runs, fields, benches, commissioning, calibration): at their top only the
    ``__init__`` and the command line."""
    for package in (ROOT / "design", ROOT / "hil" / "bench"):
        loose = sorted(p.name for p in package.glob("*.py"))
        assert loose == ["__init__.py", "cli.py"], (package.name, loose)


def test_hil_drive_loads_nothing_of_the_simulator_or_the_bench():
    """At run time too: what the vehicle's commands and modules import on a tractor (the contracts check the
    source), and no solver of the MPC, the NMPC or the LMI synthesis; a drive with a linear controller file is
    checked in tests/design/test_lean_runtime.py.

    matplotlib is not checked here: python-control (the certificate's disk margins) imports it
    itself; no module of ours does (the vehicle contract forbids it)."""
    code = ("import sys\n"
            "from hil.cli import main\n"
            "for command in ('drive', 'valve-test'):\n"
            "    try:\n        main([command, '--help'])\n    except SystemExit:\n        pass\n"
            "import hil.vehicle.drive, hil.vehicle.loop, hil.vehicle.valve_run, hil.vehicle.procedure\n"
            "bad = sorted(m for m in sys.modules"
            " if m.split('.')[0] in ('tqdm', 'dask', 'distributed', 'casadi', 'cvxpy')"
            " or m.startswith(('hil.truth', 'hil.devices', 'hil.bench')))\n"
            "print('LOADED', bad)\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "LOADED []", done.stdout[-2000:]
