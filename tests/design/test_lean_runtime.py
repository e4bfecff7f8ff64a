"""The vehicle's runtime loads only what a controller file needs.

Loading a linear controller file through the vehicle's path (``hil.vehicle.controllers``), and
``hil drive`` with one, must not import the NMPC (``design.mpc.nmpc``, casadi), the MPC or the LMI
synthesis (cvxpy): the loader imports a file kind's module when a file of that kind is read
(:mod:`design.files.load`); nor the simulator or the bench. Each check runs in a fresh
interpreter, so nothing imported by other tests counts.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from design.synthesis.robust import RobustSpec, design_robust
from hil.devices.emulate import EmulatedTractor

from design_family import family

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("casadi", "cvxpy", "design.mpc.nmpc", "design.mpc", "design.files.mpc", "design.files.nmpc")
#: Nor may ``hil drive`` load the simulator, the emulated devices or the bench.
SIMULATOR = ("hil.truth", "hil.devices", "hil.bench")

#: ``hil drive ARGS`` in a fresh interpreter; its last line is [exit status, what it loaded of the above].
DRIVE = ("import json, sys\n"
         "from hil.cli import main\n"
         "rc = main(sys.argv[1:])\n"
         f"loaded = [m for m in sys.modules if m in {HEAVY!r} or m.split('.')[0] in ('casadi', 'cvxpy')"
         f" or m.startswith({SIMULATOR!r})]\n"
         "print(json.dumps([rc, sorted(loaded)]))\n")


@pytest.fixture(scope="module")
def robust_file(tmp_path_factory) -> str:
    path = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True)).file.save(
        tmp_path_factory.mktemp("lean") / "robust.json")
    return str(path)


def _hil_drive(args: list[str], timeout: float) -> tuple[int, list[str], str]:
    done = subprocess.run([sys.executable, "-c", DRIVE, "drive", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)
    assert done.stdout.strip(), done.stderr[-2000:]
    rc, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    return rc, loaded, done.stderr


def test_loading_a_linear_file_for_the_vehicle_imports_no_nmpc_mpc_or_lmi_solver(robust_file):
    code = ("import json, sys\n"
            "from hil.vehicle.controllers import vehicle_controller\n"
            f"ctrl = vehicle_controller({robust_file!r})\n"
            f"print(json.dumps([ctrl.name, [m for m in {HEAVY!r} if m in sys.modules]]))\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    name, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert name == "linear:robust"
    assert loaded == [], f"the vehicle loaded {loaded} to run a linear file"


def test_hil_drive_with_a_linear_file_loads_none_of_them_up_to_its_ports(robust_file, tmp_path):
    """The command as typed on the tractor, to where it opens its ports: its parser, the controller file read
    and its certificate re-checked, the drive and loop modules."""
    rc, loaded, err = _hil_drive(["--bridge", str(tmp_path / "no-bridge"), "--position", str(tmp_path / "no-gps"),
                                  "--line=37,-122,37.001,-122", "--duration", "1", "--controller", robust_file,
                                  "--out", str(tmp_path / "out")], timeout=120)
    assert rc == 1 and "cannot open a serial port" in err, err[-2000:]
    assert loaded == [], f"hil drive loaded {loaded} for a linear file"


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(180)
def test_hil_drive_steers_the_emulated_tractor_with_a_linear_file_and_loads_none_of_them(robust_file, tmp_path):
    """The whole run: ports opened, the loop engaged and the linear law stepped every cycle, the log saved."""
    with EmulatedTractor(implement="none", speed=1.34, duration=60.0, seed=11) as tractor:
        rc, loaded, err = _hil_drive([*tractor.setup.drive_args(), "--controller", robust_file, "--duration", "4",
                                      "--implement", "none", "--speed", "1.34", "--out", str(tmp_path)], timeout=120)
    assert rc == 0, err[-2000:]
    result = json.loads((tmp_path / "summary.json").read_text())
    assert result["controller"] == "robust" and result["events"][0]["event"] == "engage", result["events"]
    assert result["summary"]["engaged_fraction"] > 0.5, result["summary"]
    assert loaded == [], f"hil drive loaded {loaded} for a linear file"
