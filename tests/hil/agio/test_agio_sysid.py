"""Identification passes through the emulated AgOpenGPS steer module (``hil sysid --bridge agopengps``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.cli import main as hil_main
from hil.errors import SimulatorConfigError
from hil.vehicle.agio.driver import AgioDriverConfig
from hil.vehicle.valve_map import ValveCurve
from identification.passlog import PassLog

pytestmark = pytest.mark.timeout(300)

PLAN = SysidPlan(speeds=(1.79,), implements=("none",), passes=1, duration=40.0, seed=3)


@pytest.fixture(scope="module")
def both():
    return {b: make_passes(PLAN, bridge=b)[0][1] for b in ("hc11", "agopengps")}


def _peak_lag(log: PassLog) -> int:
    """Samples (20 Hz) from the rate command to the true wheel's rate, at the best correlation."""
    u, d = log.channels["steer_rate_cmd"], log.channels["truth_wheel_angle"]
    r = np.diff(d)
    return int(np.argmax([np.corrcoef(u[:r.size - k], r[k:])[0, 1] for k in range(10)]))


def test_the_logged_angle_is_the_modules_report_and_the_input_the_ternary_rate(both):
    log = both["agopengps"]
    d = np.degrees(log.channels["wheel_angle"]) * 100
    assert np.allclose(d, np.round(d), atol=1e-6)          # PGN 253's 0.01 degree, not the 8-bit ADC
    assert not np.allclose(*(lambda v: (v, np.round(v)))(np.degrees(both["hc11"].channels["wheel_angle"]) * 100))
    u = log.channels["steer_rate_cmd"]
    assert set(np.unique(u)) <= {-0.35, 0.0, 0.35} and 0.2 < np.mean(u != 0) < 0.7
    meta = log.meta
    assert meta["bridge"] == "agopengps" and meta["agopengps"]["engages"] == 1
    assert meta["agopengps"]["engaged_fraction"] > 0.98 and meta["agopengps"]["module_loops"] >= 40 * 40 - 1
    assert meta["agopengps"]["bad_frames"] == 0 and "engaged" in meta["extra_channels"]
    assert meta["latency_s"]["wheel_angle"] == pytest.approx(0.0625)
    # the wheel follows the module's setpoint: within the driver's lead of the integral of the commands
    assert np.degrees(np.abs(log.channels["wheel_angle"] - log.channels["truth_wheel_angle"]).max()) < 3.0


def test_the_modules_angle_loop_is_in_the_data(both):
    """The wheel answers a rate command later through the module (its P-loop, the report) than
    through the valve driven directly, same seed and excitation rule."""
    assert _peak_lag(both["hc11"]) == 1
    assert _peak_lag(both["agopengps"]) == 2


def test_the_rate_follows_the_drivers_limit():
    (_, log), = make_passes(SysidPlan(speeds=(1.0,), implements=("ripper",), passes=1, duration=10.0, seed=1),
                            bridge="agopengps", module_driver=AgioDriverConfig(max_rate=0.2))
    assert set(np.unique(log.channels["steer_rate_cmd"])) <= {-0.2, 0.0, 0.2}
    assert log.meta["agopengps"]["driver"]["max_rate"] == 0.2


def test_wrong_combinations_are_refused():
    with pytest.raises(SimulatorConfigError, match="bridge must be one of"):
        make_passes(PLAN, bridge="can")
    valve = ValveCurve(full_scale=0.35, deadband=0.0, flow_exponent=1.0, left_rate=0.35, right_rate=0.35,
                       lag=0.1, angle_noise=0.005)
    with pytest.raises(SimulatorConfigError, match="closes its own"):
        make_passes(PLAN, bridge="agopengps", valve=valve)
    with pytest.raises(SimulatorConfigError, match="only to bridge='agopengps'"):
        make_passes(PLAN, module_driver=AgioDriverConfig())


def test_hil_sysid_takes_the_bridge(tmp_path, capsys):
    rc = hil_main(["sysid", "--out", str(tmp_path), "--speeds", "1.34", "--implements", "disker", "--passes", "1",
                   "--duration", "8", "--bridge", "agopengps", "--quiet", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bridge"] == "agopengps" and out["passes"] == 1
    assert PassLog.load(out["files"][0]).meta["bridge"] == "agopengps"
    with pytest.raises(SystemExit):
        hil_main(["sysid", "--out", str(tmp_path / "x"), "--bridge", "can"])


def test_the_identification_driver_leaves_the_excitation_unlimited(both):
    """With the loop's own lead limit (0.1 rad) the setpoint is cut in most slews and the models see a
    slower module than the loop runs (hil.bench.runs.sysid.SYSID_MODULE_DRIVER); the identification driver's
    limit is never reached by the excitation."""
    assert both["agopengps"].meta["agopengps"]["driver"]["max_lead"] == 0.3
    assert both["agopengps"].meta["agopengps"]["driver"]["max_windup"] == 0.3
    assert both["agopengps"].meta["agopengps"]["setpoints_limited"] == 0
    (_, loops), = make_passes(PLAN, bridge="agopengps", module_driver=AgioDriverConfig())
    moving = int(np.sum(loops.channels["steer_rate_cmd"] != 0))
    assert loops.meta["agopengps"]["setpoints_limited"] > 0.5 * moving
