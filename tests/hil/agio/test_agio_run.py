"""Bench passes through the AgOpenGPS bridge (hil.bench.runs.run.simulated_run with bridge='agopengps'):
lockstep on in-memory links, real time over UDP on 127.0.0.1, and the two agreeing."""

from __future__ import annotations

import pytest

from hil.bench.runs.run import RunSpec, simulated_run
from hil.devices.faults import LinkFault
from hil.errors import SimulatorConfigError
from hil.vehicle.controllers import vehicle_controller
from hil.vehicle.summary import summarize

pytestmark = pytest.mark.timeout(300)


def test_a_lockstep_pass_through_the_module_steers_like_one_through_the_hc11_bridge():
    logs = {b: simulated_run(RunSpec(speed=1.79, duration=30, seed=3, bridge=b), vehicle_controller("kinematic"))
            for b in ("agopengps", "hc11")}
    agio, hc11 = (summarize(logs[b]) for b in ("agopengps", "hc11"))
    assert logs["agopengps"].meta["bridge"] == "agopengps" and logs["agopengps"].meta["mode"] == "lockstep"
    bridge_trips = [e for e in logs["agopengps"].meta["events"]
                    if e["event"] == "disengage" and not e["reason"].startswith(("gps", "end of run"))]
    assert bridge_trips == [] and agio["engaged_fraction"] > 0.9   # the GPS has its own (simulated) outages
    stats = logs["agopengps"].meta["bridge_stats"]
    assert stats["checksum_errors"] == 0 and stats["reports_received"] > 550
    assert logs["agopengps"].meta["firmware"]["frames"] > 550
    # the same controller through either bridge: within 25 % of the other's 1-sigma (measured 5-10 %)
    assert agio["true_sigma_m"] == pytest.approx(hc11["true_sigma_m"], rel=0.25)


def test_link_faults_of_the_bench_act_on_the_module_link():
    spec = RunSpec(speed=1.79, duration=20, seed=1, bridge="agopengps",
                   link_faults=(LinkFault("corrupt", 5.0, 15.0, rate=0.2),))
    log = simulated_run(spec, vehicle_controller("kinematic"))
    assert log.meta["bridge_stats"]["checksum_errors"] + log.meta["firmware"]["bad_frames"] > 10


def test_an_unknown_bridge_is_refused():
    with pytest.raises(SimulatorConfigError, match="'hc11' or 'agopengps'"):
        RunSpec(bridge="agio")


@pytest.mark.realtime
def test_real_time_over_udp_loopback_agrees_with_lockstep():
    """Stated tolerance: the true 1-sigma within 35 % + 1 cm, the bias within 2 cm (different noise
    realisations: the real-time host's timing differs from the virtual clock's)."""
    spec = RunSpec(speed=1.79, duration=20, seed=2, bridge="agopengps")
    rt = simulated_run(RunSpec(**{**spec.__dict__, "realtime": True}), vehicle_controller("kinematic"))
    ls = simulated_run(spec, vehicle_controller("kinematic"))
    a, b = summarize(rt), summarize(ls)
    assert rt.meta["mode"] == "realtime-udp" and a["disengagements"] == b["disengagements"]
    assert abs(a["true_sigma_m"] - b["true_sigma_m"]) <= 0.35 * b["true_sigma_m"] + 0.01
    assert abs(a["true_bias_m"] - b["true_bias_m"]) <= 0.02


REFERENCE = __import__("pathlib").Path(__file__).resolve().parents[2] / "data" / "hil_reference" / "controllers"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["robust.json", "mpc.json"])
def test_robust_and_mpc_through_the_module_within_1_15x_of_the_hc11_bridge_at_the_hardest_cell(name):
    """Disker at 2.91 m/s (the paper's worst cell), seed 0, 60 s: designed on HC11-bridge models and run
    unchanged through the module; the setpoint lead (LEAD_TIME) is what makes it hold (without it the
    robust controller measured 11.9 cm against 5.0 cm)."""
    from hil.bench.runs.campaign import make_controller
    sig = {}
    for bridge in ("agopengps", "hc11"):
        log = simulated_run(RunSpec(implement="disker", speed=2.91, duration=60, seed=0, bridge=bridge),
                            make_controller(str(REFERENCE / name)))
        s = summarize(log)
        assert s["disengagements"] == 0
        sig[bridge] = s["true_sigma_m"]
    assert sig["agopengps"] <= 1.15 * sig["hc11"]


def test_the_true_bias_differs_from_the_measured_one_by_the_gps_slow_error_through_either_bridge():
    """A bias of -3.5 cm true against -0.6 cm measured: the loop zeros the *measured* cross-track, so the
    truth carries minus the mean of the receiver's slow (multipath) error over the statistics window: 2.9 cm
    on seed 0, 0.2 cm on seed 1 (``gps.multipath`` 2 cm, 30 s). Nothing of the module: the gap is the same
    through the HC11 bridge (measured 2.87 cm both ways on seed 0, 0.31-0.32 on seed 1)."""
    import numpy as np

    from hil.devices.plant import SimulatedTractor
    from hil.truth.conditions import condition_for

    for seed in (0, 1):
        sim = SimulatedTractor(condition_for("none", 1.79), 61.0, seed).sim
        mp_y = sim.gps_errors.multipath[0, :, 1]
        t_mp = np.arange(mp_y.size) / sim.params.gps.position_rate
        gaps = {}
        for bridge in ("agopengps", "hc11"):
            log = simulated_run(RunSpec(speed=1.79, duration=60, seed=seed, bridge=bridge), vehicle_controller("kinematic"))
            s = summarize(log)
            t = log.times["t"]
            window = (log.channels["engaged"] > 0.5) & (t >= s["first_engage_s"] + 5.0)
            multipath = np.interp(t[window] - sim.params.gps.position_latency, t_mp, mp_y).mean()
            gaps[bridge] = s["measured_bias_m"] - s["true_bias_m"]
            assert gaps[bridge] == pytest.approx(multipath, abs=0.004)
        assert gaps["agopengps"] == pytest.approx(gaps["hc11"], abs=0.002)


@pytest.mark.slow
def test_the_setpoint_integral_does_not_wind_up_in_a_saturated_approach():
    """None at 2.91 m/s, seeds 0 and 1, the reference robust controller (designed on HC11-bridge models):
    without the integral's own limit (MAX_WINDUP) the setpoint ran 0.1 rad ahead of a wheel that could
    not follow and the approach oscillated for 15 s (seed 1: 10.0 cm true 1-sigma against 5.7 through the
    HC11 bridge, 1.44x); with it each seed within 1.15x of the HC11 bridge. The controller file's own line
    acquisition (integrators held during the approach) also
    keeps this approach from saturating, so the test now guards both."""
    from hil.bench.runs.campaign import make_controller
    for seed in (0, 1):
        sig = {}
        for bridge in ("agopengps", "hc11"):
            log = simulated_run(RunSpec(implement="none", speed=2.91, duration=60, seed=seed, bridge=bridge),
                                make_controller(str(REFERENCE / "robust.json")))
            sig[bridge] = summarize(log)["true_sigma_m"]
        assert sig["agopengps"] <= 1.15 * sig["hc11"], (seed, sig)
