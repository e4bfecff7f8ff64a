"""The vehicle's runtime loads only what a controller file needs.

Loading a linear controller file through the vehicle's path (``hil.vehicle.controllers``)
must not import the NMPC (``design.mpc.nmpc``, casadi) or the LMI synthesis (cvxpy): the loader
imports a file kind's module when a file of that kind is read (:mod:`design.files.load`).
Run in a fresh interpreter, so nothing imported by other tests counts.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from design.synthesis.robust import RobustSpec, design_robust

from design_family import family

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("casadi", "cvxpy", "design.mpc.nmpc", "design.mpc", "design.files.mpc", "design.files.nmpc")


def test_loading_a_linear_file_for_the_vehicle_imports_no_nmpc_mpc_or_lmi_solver(tmp_path):
    path = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True)).file.save(
        tmp_path / "robust.json")
    code = ("import json, sys\n"
            "from hil.vehicle.controllers import vehicle_controller\n"
            f"ctrl = vehicle_controller({str(path)!r})\n"
            f"print(json.dumps([ctrl.name, [m for m in {HEAVY!r} if m in sys.modules]]))\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    name, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert name == "linear:robust"
    assert loaded == [], f"the vehicle loaded {loaded} to run a linear file"
