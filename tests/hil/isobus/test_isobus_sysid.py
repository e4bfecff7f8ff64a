"""Identification passes through the emulated ISO 11783 steering controller (``hil sysid --bridge isobus``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.cli import main as hil_main
from hil.errors import SimulatorConfigError
from hil.vehicle.agio.driver import AgioDriverConfig
from hil.vehicle.isobus.driver import IsobusDriverConfig
from hil.vehicle.valve_map import ValveCurve
from identification.passlog import PassLog

pytestmark = pytest.mark.timeout(300)

PLAN = SysidPlan(speeds=(1.79,), implements=("none",), passes=1, duration=40.0, seed=3)


@pytest.fixture(scope="module")
def both():
    return {b: make_passes(PLAN, bridge=b)[0][1] for b in ("hc11", "isobus")}


def _peak_lag(log: PassLog) -> int:
    """Samples (20 Hz) from the rate command to the true wheel's rate, at the best correlation."""
    u, d = log.channels["steer_rate_cmd"], log.channels["truth_wheel_angle"]
    r = np.diff(d)
    return int(np.argmax([np.corrcoef(u[:r.size - k], r[k:])[0, 1] for k in range(10)]))


def test_the_logged_angle_is_the_estimated_curvatures_and_the_input_the_ternary_rate(both):
    log = both["isobus"]
    counts = log.channels["wheel_angle"] * 1e4
    assert np.allclose(counts, np.round(counts), atol=1e-6)     # the loop's 0.1 mrad counts of atan(L kappa)
    u = log.channels["steer_rate_cmd"]
    assert set(np.unique(u)) <= {-0.35, 0.0, 0.35} and 0.2 < np.mean(u != 0) < 0.7
    meta = log.meta
    assert meta["bridge"] == "isobus" and meta["isobus"]["engages"] == 1
    assert meta["isobus"]["engaged_fraction"] > 0.98 and meta["isobus"]["bad_frames"] == 0
    assert meta["isobus"]["controller_reports"] >= 40 * 10 - 3 and "engaged" in meta["extra_channels"]
    # the newest report is 0 or 50 ms old at the 20 Hz polls (reports every 100 ms)
    assert meta["latency_s"]["wheel_angle"] == pytest.approx(0.025)
    # the wheel follows the curvature commanded: within a report and the sensor's resolution of the truth
    assert np.degrees(np.abs(log.channels["wheel_angle"] - log.channels["truth_wheel_angle"]).max()) < 3.0


def test_commands_start_after_the_handshake(both):
    """The guidance system's claim stands at 0.25 s; its first "not intended to steer" clears the
    controller's reset, which the report of 0.3 s shows: the first cycle commanding is that of 0.3 s."""
    log = both["isobus"]
    t, engaged, u = log.times["t"], log.channels["engaged"], log.channels["steer_rate_cmd"]
    first = int(np.argmax(engaged > 0))
    assert t[first] == pytest.approx(0.30) and not np.any(u[:first])
    assert log.meta["isobus"]["intended_sent"] == int(engaged.sum())


def test_the_controllers_delay_is_in_the_data(both):
    """The wheel answers a rate command later through the controller (its curvature filter, rate limit,
    valve loop and report period) than through the valve driven directly, same seed and excitation rule."""
    assert _peak_lag(both["hc11"]) == 1
    assert _peak_lag(both["isobus"]) >= 3


def test_the_vehicles_driver_settings_by_default_and_others_on_request(both):
    driver = both["isobus"].meta["isobus"]["driver"]
    assert driver["max_windup"] == pytest.approx(0.115) and driver["wheelbase"] == pytest.approx(2.85)
    (_, log), = make_passes(SysidPlan(speeds=(1.0,), implements=("ripper",), passes=1, duration=10.0, seed=1),
                            bridge="isobus", module_driver=IsobusDriverConfig(wheelbase=2.85, max_rate=0.2))
    assert set(np.unique(log.channels["steer_rate_cmd"])) <= {-0.2, 0.0, 0.2}
    assert log.meta["isobus"]["driver"]["max_rate"] == 0.2


def test_wrong_combinations_are_refused():
    valve = ValveCurve(full_scale=0.35, deadband=0.0, flow_exponent=1.0, left_rate=0.35, right_rate=0.35,
                       lag=0.1, angle_noise=0.005)
    with pytest.raises(SimulatorConfigError, match="closes its own"):
        make_passes(PLAN, bridge="isobus", valve=valve)
    with pytest.raises(SimulatorConfigError, match="'isobus' \\(an IsobusDriverConfig\\), got a AgioDriverConfig"):
        make_passes(PLAN, bridge="isobus", module_driver=AgioDriverConfig())
    with pytest.raises(SimulatorConfigError, match="got a IsobusDriverConfig with bridge='agopengps'"):
        make_passes(PLAN, bridge="agopengps", module_driver=IsobusDriverConfig(wheelbase=2.85))


def test_hil_sysid_takes_the_isobus_bridge(tmp_path, capsys):
    rc = hil_main(["sysid", "--out", str(tmp_path), "--speeds", "1.34", "--implements", "disker", "--passes", "1",
                   "--duration", "8", "--bridge", "isobus", "--quiet", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bridge"] == "isobus" and out["passes"] == 1
    assert PassLog.load(out["files"][0]).meta["bridge"] == "isobus"
