"""Run logs stay the same in distribution: the 22 reference cases before vs now.

``tests/data/hil_reference/reference_runs.json`` holds, for 22 closed-loop lockstep passes of 60 s
(12 kinematic-LQR passes over 3 implements x 2 speeds x 2 seeds, the demo's robust and central-LQR
controller files over the 3 implements, the oracle, and link-, plant- and mixed-fault passes), the
statistics recorded on the code before the equations' twins were removed (commit and recipe in the
JSON and in ``tests/data/hil_reference/README.md``). Each case is re-run here from its spec in the
JSON and compared within these tolerances (bit-identity is not asked for):

* cross-track bias (mean over the statistics window, measured and true): within
  ``BIAS_TOL_M + BIAS_TOL_SIGMAS * sigma_ref``;
* cross-track 1-sigma (measured and true): within ``SIGMA_TOL_REL * sigma_ref + SIGMA_TOL_M``;
* heading error and wheel angle 1-sigma within ``CHANNEL_TOL_REL`` (relative);
* engaged fraction within ``ENGAGED_TOL``, disengagements within ``DISENGAGE_TOL`` of the reference,
  and the same set of disengage reasons (their kinds, without the numbers in them).

The fast test re-runs four cases (the three fault cases and one plain pass); the whole set is
``slow`` (about 10-20 s of CPU).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hil.bench.runs.campaign import make_controller
from hil.devices.faults import LinkFault
from hil.bench.runs.run import RunSpec, simulated_run
from hil.vehicle.summary import summarize

DATA = Path(__file__).resolve().parents[1] / "data" / "hil_reference"
REFERENCE = json.loads((DATA / "reference_runs.json").read_text())
RUNS = {r["case"]["name"]: r for r in REFERENCE["runs"]}

BIAS_TOL_M = 0.002          # m
BIAS_TOL_SIGMAS = 0.15      # of the reference 1-sigma
SIGMA_TOL_REL = 0.10
SIGMA_TOL_M = 0.001         # m
CHANNEL_TOL_REL = 0.15
ENGAGED_TOL = 0.02
DISENGAGE_TOL = 1

FAST = ("kinematic_disker_2.91_seed0", "link_faults_kinematic_disker_1.79_seed2",
        "plant_faults_kinematic_ripper_1.79_seed3", "mixed_faults_robust_disker_2.91_seed6")


def _spec(case: dict) -> RunSpec:
    faults = tuple(LinkFault(k, a, b, rate=r, direction=d) for k, a, b, r, d in case.get("link_faults", ()))
    return RunSpec(implement=case["implement"], speed=case["speed"], duration=case.get("duration", 60.0),
                   seed=case["seed"], override=tuple(map(tuple, case.get("override", ()))),
                   stuck_valve=tuple(map(tuple, case.get("stuck_valve", ()))),
                   gps_outage=tuple(map(tuple, case.get("gps_outage", ()))),
                   rtk_float=tuple(map(tuple, case.get("rtk_float", ()))), link_faults=faults)


def _reasons(events: list[dict]) -> set[str]:
    """The kinds of disengage reasons (numbers left out: '0.35 s old' and '0.36 s old' are one kind)."""
    return {re.sub(r"-?\d+(\.\d+)?", "#", e["reason"]) for e in events if e["event"] == "disengage"}


def _window_stats(log) -> dict[str, tuple[float, float]]:
    """(bias, 1-sigma) of heading error and wheel angle over summarize's statistics window."""
    t = log.times["t"]
    engaged = log.channels["engaged"] > 0.5
    starts = np.array([e["t"] for e in log.meta["events"] if e["event"] == "engage"])
    i = np.searchsorted(starts, t + 1e-9, side="right") - 1
    last = np.where(i >= 0, starts[np.maximum(i, 0)], -np.inf)
    window = engaged & (t >= last + 5.0)
    return {k: (float(log.channels[k][window].mean()), float(log.channels[k][window].std()))
            for k in ("heading_error", "wheel_angle", "truth_heading_error", "truth_wheel_angle")}


def check_case(name: str) -> list[str]:
    """Re-run one reference case; return what is outside the tolerances (empty: within)."""
    ref = RUNS[name]
    case = ref["case"]
    spec = case["controller"]
    ctrl = make_controller(str(DATA / "controllers" / spec) if spec.endswith(".json") else spec,
                           case["implement"], case["speed"])
    log = simulated_run(_spec(case), ctrl)
    s, r = summarize(log), ref["summary"]
    bad = []
    for which in ("measured", "true"):
        sig = r[f"{which}_sigma_m"]
        if abs(s[f"{which}_bias_m"] - r[f"{which}_bias_m"]) > BIAS_TOL_M + BIAS_TOL_SIGMAS * sig:
            bad.append(f"{which} bias {s[f'{which}_bias_m']:.4f} m, reference {r[f'{which}_bias_m']:.4f} m")
        if abs(s[f"{which}_sigma_m"] - sig) > SIGMA_TOL_REL * sig + SIGMA_TOL_M:
            bad.append(f"{which} 1-sigma {s[f'{which}_sigma_m']:.4f} m, reference {sig:.4f} m")
    for k, (_, sigma) in _window_stats(log).items():
        want = ref["channels"][k]["sigma"]
        if abs(sigma - want) > CHANNEL_TOL_REL * want:
            bad.append(f"{k} 1-sigma {sigma:.5f}, reference {want:.5f}")
    if abs(s["engaged_fraction"] - r["engaged_fraction"]) > ENGAGED_TOL:
        bad.append(f"engaged fraction {s['engaged_fraction']:.3f}, reference {r['engaged_fraction']:.3f}")
    if abs(s["disengagements"] - r["disengagements"]) > DISENGAGE_TOL:
        bad.append(f"{s['disengagements']} disengagements, reference {r['disengagements']}")
    if _reasons(log.meta["events"]) != _reasons(ref["events"]):
        bad.append(f"disengage reasons {sorted(_reasons(log.meta['events']))}, "
                   f"reference {sorted(_reasons(ref['events']))}")
    return bad


def test_the_reference_set_is_the_22_cases_and_says_how_it_was_made():
    assert len(RUNS) == 22
    assert REFERENCE["commit"] and REFERENCE["made_by"]
    kinds = [r["case"]["controller"] for r in REFERENCE["runs"]]
    assert kinds.count("kinematic") == 14 and kinds.count("robust.json") == 4 and kinds.count("central-lqr.json") == 3


@pytest.mark.parametrize("name", FAST)
def test_fault_cases_and_one_plain_pass_match_the_reference_in_distribution(name):
    assert check_case(name) == []


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in RUNS if n not in FAST])
def test_every_reference_case_matches_in_distribution(name):
    assert check_case(name) == []
