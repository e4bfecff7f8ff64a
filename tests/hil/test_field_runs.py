"""Closed-loop runs on fields: the loop follows a route of passes and headland turns.

The fields here are small files written with :func:`gnss.field_io.field_to_dict` (a hairpin
field: passes 3 m apart, so every headland turn is a bulb turn whose legs come back within a
few metres of each other), so the runs are short; the named fields run in ``slow`` tests.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from design.laws.controller import KinematicLQRController
from gnss.curve import ArcPath
from gnss.field import Field
from gnss.field_io import field_to_dict
from hil.bench.fields.metrics import field_metrics, jumps
from hil.bench.runs.field_route import field_run
from hil.bench.runs.run import RunSpec, simulated_run
from hil.cli import main as hil_main
from hil.truth.params import SimParams
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.loop import PART_KINDS


def write_field(path, reference: ArcPath, width: float, passes: int, name: str) -> str:
    path.write_text(json.dumps(field_to_dict(Field(name, reference, width, passes))))
    return str(path)


@pytest.fixture(scope="module")
def hairpin(tmp_path_factory) -> str:
    """Three straight 40 m passes 3 m apart: the U-turns between them are bulb turns (hairpins)."""
    return write_field(tmp_path_factory.mktemp("fields") / "hairpin.json", ArcPath((0, 0), 0.0, [(40.0, 0.0)]),
                       3.0, 3, "hairpin")


@pytest.fixture(scope="module")
def curved(tmp_path_factory) -> str:
    """Two passes with a 40 m straight, a 50 m-radius bend of 45 degrees and a straight, 6 m apart."""
    ref = ArcPath((0, 0), 0.0, [(40.0, 0.0), (50.0 * math.pi / 4, 1 / 50.0), (30.0, 0.0)])
    return write_field(tmp_path_factory.mktemp("fields") / "bend.json", ref, 6.0, 2, "bend")


def run_field(field: str, controller, speed: float = 1.79, implement: str = "none", seed: int = 1,
              params: SimParams | None = None, **kw):
    fr = field_run(field, params or SimParams(), speed)
    spec = RunSpec(implement=implement, speed=speed, duration=fr.path.length / speed + 5.0, seed=seed, field=field,
                   **kw)
    return fr, simulated_run(spec, controller, params)


#: GPS without outages: a disengagement inside a turn would be the receiver's, not the route's
NO_DROPOUTS = SimParams().with_overrides({"gps.dropout_rate": 0.0})


@pytest.fixture(scope="module")
def hairpin_run(hairpin):
    return run_field(hairpin, KinematicLQRController(), params=NO_DROPOUTS)


def test_no_wrong_segment_jumps_through_hairpin_turns_in_closed_loop(hairpin_run):
    fr, log = hairpin_run
    ch = log.channels
    kinds = {v: k for k, v in PART_KINDS.items()}
    seen = {kinds.get(int(k)) for k in np.unique(ch["part_kind"])}
    assert {"straight", "turn"} <= seen
    # the route was driven to its end, the loop engaged through the turns
    assert ch["truth_along_track"][-1] > fr.path.length - 2.0
    m = field_metrics(log, 3.0, fr.curve_entries())
    assert len(m["turns"]) == 2 and all(t["engaged_in_turn"] for t in m["turns"])
    assert m["wrong_segment_jumps"] == 0 and m["truth_station_jumps"] == 0
    assert m["off_route_s"] == 0.0 and m["route_driven"] > 0.99
    # the station the loop saw stays with the truth's (the same route, placed on the Earth)
    on = (ch["integrity"] <= 1) & (ch["engaged"] > 0.5)
    assert np.max(np.abs(ch["station"][on] - ch["truth_along_track"][on])) < 1.0
    # the same tracks projected globally on the route jump to the other leg of a hairpin: the
    # counter sees that (so the zero above is not a counter that cannot count)
    glob = fr.path.errors(ch["truth_x"], ch["truth_y"]).station
    assert jumps(glob, ch["speed"], np.ones(glob.size, dtype=bool), 0.05) > 0


def test_field_figures_of_the_hairpin_run(hairpin_run):
    fr, log = hairpin_run
    m = field_metrics(log, 3.0, fr.curve_entries())
    for t in m["turns"]:        # out of each turn and settled on the next pass within a few seconds
        assert t["settle_time_s"] is not None and t["settle_time_s"] < 10.0
        assert t["overshoot_m"] < 0.3
    sp = m["spacing"]
    assert sp["samples"] > 500 and abs(sp["mean_m"]) < 0.05 and sp["sigma_m"] < 0.10
    assert m["straight"]["samples"] > 1000 and abs(m["straight"]["bias_m"]) < 0.05
    assert m["curve"]["samples"] == 0


def test_each_pass_carries_its_measured_bias_and_the_report_names_the_worst_pass(hairpin_run):
    from hil.bench.fields.runs import worst_pass_bias
    fr, log = hairpin_run
    m = field_metrics(log, 3.0, fr.curve_entries())
    ch = log.channels
    for p in m["passes"]:       # the measured bias is the loop's cross-track over the pass's scored cycles
        st = p["straight"]
        assert st["samples"] > 100 and st["measured_bias_m"] is not None
        assert abs(st["measured_bias_m"] - st["bias_m"]) < 0.05          # the GPS's error averaged over a pass
        assert st["measured_bias_m"] != st["bias_m"]
    assert np.ptp([p["straight"]["measured_bias_m"] for p in m["passes"]]) < np.ptp(ch["cross_track"])
    w = worst_pass_bias(m["passes"])
    biases = [p["straight"]["bias_m"] for p in m["passes"]]
    assert abs(w["bias_m"]) == max(abs(b) for b in biases) and w["bias_m"] in biases
    assert m["passes"][w["pass"]]["straight"]["measured_bias_m"] == w["measured_bias_m"]
    synthetic = [{"pass": 0, "reached": True, "straight": {"bias_m": 0.004, "measured_bias_m": 0.0}},
                 {"pass": 1, "reached": True, "straight": {"bias_m": -0.012, "measured_bias_m": -0.001}},
                 {"pass": 2, "reached": False}]
    assert worst_pass_bias(synthetic) == {"pass": 1, "bias_m": -0.012, "measured_bias_m": -0.001}
    assert worst_pass_bias([{"pass": 0, "reached": False}])["bias_m"] is None


class PreviewRecorder(KinematicLQRController):
    """The kinematic LQR asking for a curvature preview, keeping every measurement it is given."""

    name = "preview-recorder"
    preview_request = (8, 0.25)

    def __init__(self) -> None:
        super().__init__()
        self.seen = []

    def step(self, m):
        self.seen.append(m)
        return super().step(m)


def test_the_loop_feeds_curvature_and_the_preview_asked_for(curved):
    ctrl = PreviewRecorder()
    fr, log = run_field(curved, ctrl)
    k = np.array([m.curvature for m in ctrl.seen])
    # the bend's own curvature while the loop is on it, the turn's up to the planned limit
    assert np.isclose(k, 1 / 50.0).sum() > 300 and np.isclose(k, 0.0).sum() > 300
    assert k.max() <= fr.limits.kappa_max + 1e-9 and k.max() > 0.1
    pv = np.array([m.preview for m in ctrl.seen])
    assert pv.shape == (len(ctrl.seen), 8)
    # the preview's first stretch ends 0.25 s of travel ahead: it sees the bend before the curvature does
    first = np.argmax(pv[:, -1] > 0.0)
    assert 0 < first < np.argmax(k > 0.0)
    bend = np.isclose(k, 1 / 50.0)
    assert np.allclose(pv[bend][20:-60], 1 / 50.0)      # inside the bend, 2 s of travel ahead is bend too
    # on an AB line the same controller gets zeros
    ab = PreviewRecorder()
    simulated_run(RunSpec(speed=1.79, duration=3.0, seed=1), ab)
    assert ab.seen and all(m.preview == (0.0,) * 8 and m.curvature == 0.0 for m in ab.seen)


def test_a_bad_preview_request_is_refused(curved):
    ctrl = PreviewRecorder()
    for bad in ((8, 0.0), (-1, 0.1), ("8", 0.1), (8,), 8):
        ctrl.preview_request = bad
        with pytest.raises(VehicleConfigError, match="preview_request"):
            run_field(curved, ctrl)


def test_the_implement_is_raised_in_headland_turns_only(hairpin):
    fr, log = run_field(hairpin, KinematicLQRController(), implement="disker")
    ch = log.channels
    turn = ch["part_kind"] == PART_KINDS["turn"]
    raised = ch["truth_implement_raised"] > 0.5
    on_route = ch["truth_along_track"] < fr.path.length
    # by the truth's station (the loop's own lags by the GPS latency): raised exactly on the turns
    in_turn = np.zeros(turn.shape, dtype=bool)
    for p in fr.route.parts:
        if p.kind == "turn":
            in_turn |= (ch["truth_along_track"] >= p.start) & (ch["truth_along_track"] < p.end)
    assert raised.any() and np.array_equal(raised[on_route], in_turn[on_route])
    assert np.mean(turn[raised]) > 0.9


def test_a_raised_implement_leaves_the_soil_and_comes_back():
    from hil.truth.conditions import condition_for
    from hil.truth.simulator import SOIL_CHANNELS, TractorSimulator
    sim = TractorSimulator([condition_for("disker", 1.79)], 10.0, [3], scalar=True)
    drawn = {f: getattr(sim.exo, f).copy() for f in (*SOIL_CHANNELS, "front_load")}
    sim.steps(40)
    sim.set_implement_raised(True)
    assert np.all(sim.exo.draft[0, 40:] == 0.0) and np.all(sim.exo.gang_pull[0, 40:] == 0.0)
    assert np.array_equal(sim.exo.draft[0, :40], drawn["draft"][0, :40])
    assert np.all(sim.exo.front_load[0, 40:] == SimParams().disker.front_load_factor)
    sim.steps(60)
    sim.set_implement_raised(False)
    assert np.array_equal(sim.exo.draft[0, 100:], drawn["draft"][0, 100:])
    assert np.all(sim.exo.draft[0, 40:100] == 0.0)
    # and the tractor feels it: the same seed with the implement kept in the soil ends elsewhere
    other = TractorSimulator([condition_for("disker", 1.79)], 10.0, [3], scalar=True)
    sim.steps(100)
    other.steps(200)
    assert sim.truth_scalar()["hitch_angle"] != other.truth_scalar()["hitch_angle"]


def test_hil_run_on_a_field_writes_its_figures(tmp_path, hairpin):
    out = tmp_path / "run"
    rc = hil_main(["run", "--controller", "kinematic", "--field", hairpin, "--passes", "2", "--speed", "2.24",
                   "--out", str(out), "--json", "--quiet"])
    assert rc == 0
    res = json.loads((out / "summary.json").read_text())
    f = res["field"]
    assert f["name"] == "hairpin" and f["wrong_segment_jumps"] == 0 and len(f["turns"]) == 1
    for name in ("overhead.png", "overhead_closeup.png", "passes.png"):
        assert (out / name).stat().st_size > 0


def test_hil_run_refuses_field_options_that_do_not_fit(tmp_path, hairpin, capsys):
    assert hil_main(["run", "--controller", "kinematic", "--passes", "2", "--out", str(tmp_path / "a")]) == 1
    assert "need a field" in capsys.readouterr().err
    assert hil_main(["run", "--controller", "kinematic", "--field", hairpin, "--passes", "9",
                     "--out", str(tmp_path / "b")]) == 1
    assert "passes must be 1-3" in capsys.readouterr().err
    assert hil_main(["run", "--controller", "kinematic", "--field", "no-such-field",
                     "--out", str(tmp_path / "c")]) == 1


def test_hil_run_with_the_oracle_on_a_field_runs_the_field_oracle(tmp_path, curved, capsys):
    # measured on the bend at 1.79 m/s, seed 0, no GPS outages: the field oracle's curve bias per pass -2.1 and
    # -2.7 cm, worst curve entry 11.7 cm; the bare straight-line oracle (what `hil run --field` built before)
    # 29.5 and -37.9 cm, 54.8 cm
    out = tmp_path / "oracle"
    assert hil_main(["run", "--controller", "oracle", "--field", curved, "--speed", "1.79", "--out", str(out),
                     "--set", "gps.dropout_rate=0", "--quiet"]) == 0
    f = json.loads((out / "summary.json").read_text())["field"]
    assert len(f["passes"]) == 2 and f["wrong_segment_jumps"] == 0 and f["route_driven"] > 0.99
    assert all(abs(p["curve"]["bias_m"]) <= 0.05 for p in f["passes"]), f["passes"]
    assert f["curve_entry_worst_m"] <= 0.2
    capsys.readouterr()
    # its weights are the field oracle's: accepted with --field, refused on an AB line, checked by name
    assert hil_main(["run", "--controller", "oracle?cross_track=0.025", "--field", curved, "--passes", "1",
                     "--duration", "5", "--out", str(tmp_path / "w"), "--quiet"]) == 0
    assert hil_main(["run", "--controller", "oracle?cross_track=0.025", "--duration", "5",
                     "--out", str(tmp_path / "ab"), "--quiet"]) == 1
    assert "the oracle's weights are for field runs (--field)" in capsys.readouterr().err
    assert not (tmp_path / "ab").exists()
    with pytest.raises(SystemExit) as e:
        hil_main(["run", "--controller", "oracle?crosstrack=0.025", "--field", curved, "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and "crosstrack" in capsys.readouterr().err
    assert hil_main(["compare", "oracle?cross_track=0.025", "--conditions", "none:1.79", "--seeds", "1",
                     "--out", str(tmp_path / "cmp")]) == 1
    assert "the oracle's weights are for field runs (--fields)" in capsys.readouterr().err


def test_hil_compare_refuses_an_empty_field_list_and_options_it_cannot_use(tmp_path, hairpin, capsys):
    with pytest.raises(SystemExit) as e:     # an empty list was an AB comparison before
        hil_main(["compare", "kinematic", "--fields", ",", "--out", str(tmp_path / "a")])
    assert e.value.code == 2 and "--fields" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    for extra in (["--duration", "30"], ["--bridge", "agopengps"], ["--realtime", "none:1.79"]):
        assert hil_main(["compare", "kinematic", "--fields", hairpin, *extra, "--out", str(tmp_path / "b")]) == 1
        assert "--fields runs whole routes" in capsys.readouterr().err
    assert hil_main(["compare", "kinematic", "--passes", "2", "--out", str(tmp_path / "c")]) == 1
    assert "--passes needs --fields" in capsys.readouterr().err


@pytest.mark.slow
def test_hil_compare_on_fields_writes_a_report(tmp_path, hairpin):
    out = tmp_path / "cmp"
    rc = hil_main(["compare", "kinematic", "stanley", "--fields", hairpin, "--conditions", "none:1.79",
                   "--seeds", "1", "--passes", "2", "--workers", "1", "--out", str(out), "--quiet"])
    assert rc == 0
    text = (out / "fields.md").read_text()
    assert text.count("| hairpin |") == 2
    rows = json.loads((out / "fields.json").read_text())["rows"]
    assert {r["controller"] for r in rows} == {"kinematic", "stanley"} and all(r["jumps"] == 0 for r in rows)
    assert (out / "hairpin_overhead.png").exists()
    # resumes: a second call runs nothing new and gives the same rows
    assert hil_main(["compare", "kinematic", "stanley", "--fields", hairpin, "--conditions", "none:1.79",
                     "--seeds", "1", "--passes", "2", "--workers", "1", "--out", str(out), "--quiet"]) == 0
    assert json.loads((out / "fields.json").read_text())["rows"] == rows


def test_field_geometry_places_a_route_as_the_receivers_place_the_simulator_frame(curved):
    from gnss.field import FieldGeometry
    fr = field_run(curved, SimParams(), 1.79)
    for geo in (FieldGeometry(), FieldGeometry(line_yaw=math.radians(-135.0))):
        placed = geo.place(fr.path)
        s = np.linspace(-5.0, fr.path.length + 5.0, 400)
        x, y, th = fr.path.pose(s)
        e, n, th_enu = placed.pose(s)
        east, north = np.array([geo.line_to_enu(a, b) for a, b in zip(x, y)]).T
        assert np.max(np.hypot(e - east, n - north)) < 1e-9
        # a vehicle heading along the route in the simulator's frame is the placed route's direction in ENU
        yaw = np.array([geo.yaw(t) for t in th])           # yaw of a heading psi = th from the frame's x axis
        assert np.allclose(np.cos(np.pi / 2 - yaw), np.cos(th_enu)) and np.allclose(np.sin(np.pi / 2 - yaw),
                                                                                  np.sin(th_enu))


class FullLock(KinematicLQRController):
    """Steers left at the loop's full rate whatever it measures (a U-turn tighter than the tractor can drive)."""

    name = "full-lock"

    def step(self, m):
        return 0.35


def test_a_wheel_held_at_its_stop_is_not_a_steering_fault():
    log = simulated_run(RunSpec(speed=1.79, duration=8.0, seed=1), FullLock(), NO_DROPOUTS)
    ch = log.channels
    assert ch["truth_wheel_angle"].max() > SimParams().steering.max_wheel_angle - 0.01    # it reached the stop
    reasons = [e["reason"] for e in log.meta["events"] if e["event"] == "disengage"]
    assert not any("not responding" in r for r in reasons), reasons
    assert ch["engaged"][-20:].all()


def test_a_driver_takes_the_wheel_when_the_autosteer_lets_go_in_a_curve(curved):
    # RTK float from inside the bend (40 m in: 22 s) to past its end (79 m: 44 s): the loop lets go
    kw = dict(params=NO_DROPOUTS, rtk_float=((30.0, 50.0),))
    fr, alone = run_field(curved, KinematicLQRController(), field_driver=False, **kw)
    _, driven = run_field(curved, KinematicLQRController(), **kw)
    for log in (alone, driven):
        assert any("rtk_float" in e["reason"] for e in log.meta["events"] if e["event"] == "disengage")
    # nobody at the wheel: the held wheel keeps turning the tractor off the route after the bend
    m_alone = field_metrics(alone, 6.0, fr.curve_entries())
    assert np.abs(alone.channels["truth_cross_track"]).max() > 2.0 and m_alone["off_route_s"] > 0
    # the driver steers it back and hands over: the autosteer drives the rest of the route
    m = field_metrics(driven, 6.0, fr.curve_entries())
    assert driven.meta["field"]["driver_takeovers"] >= 1        # (again while the fix stays bad)
    assert m["off_route_s"] == 0.0 and m["route_driven"] > 0.99
    assert np.abs(driven.channels["truth_cross_track"]).max() < 1.0
    t = driven.times["t"]
    assert driven.channels["engaged"][t > 60.0].all()


def test_pass_spacing_is_measured_to_the_neighbour_track_and_never_across_its_gaps():
    from hil.bench.fields.metrics import track_distance
    s = np.arange(0.0, 55.0, 0.1)
    keep = ((s < 20.0) | (s > 30.0)) & (s < 50.0)       # 10 m of the neighbour left out (a disengagement)
    arc = np.column_stack([30.0 * np.cos(s / 30.0), 30.0 * np.sin(s / 30.0)])
    outer = np.column_stack([36.05 * np.cos(s / 30.0), 36.05 * np.sin(s / 30.0)])
    d = track_distance(outer, arc[keep]) - 6.0
    assert np.nanmax(np.abs(d - 0.05)) < 1e-9            # exact on an arc, where measured
    assert np.isnan(d[(s > 20.5) & (s < 29.5)]).all()   # not to the 10 m chord across the gap (0.4 m off)
    assert np.isnan(d[s > 50.5]).all() and np.isfinite(d[(s > 1) & (s < 19)]).all()


class PartRecorder(KinematicLQRController):
    """The kinematic LQR, recording what the loop tells it of the route's parts (``enter_part``)."""

    def __init__(self) -> None:
        super().__init__()
        self.told: list[tuple[int, str]] = []    # (cycle of the step that follows, kind)
        self.steps = 0

    def enter_part(self, kind: str) -> None:
        self.told.append((self.steps, kind))

    def step(self, m):
        self.steps += 1
        return super().step(m)


def test_the_loop_tells_the_controller_every_change_of_route_part(hairpin):
    ctrl = PartRecorder()
    _, log = run_field(hairpin, ctrl, params=NO_DROPOUTS)
    engaged = log.channels["engaged"] > 0.5
    kinds = log.channels["part_kind"][engaged]          # the part at the loop's station, every engaged cycle
    names = {**{float(v): k for k, v in PART_KINDS.items()}, -1.0: ""}     # -1: past the route's end
    changes = [0] + [i for i in range(1, kinds.size) if kinds[i] != kinds[i - 1]]
    assert ctrl.steps == kinds.size and len(log.meta["events"]) == 2          # one engage, one stop at the end
    assert ctrl.told == [(i, names[kinds[i]]) for i in changes]             # told before the step, each change once
    assert [k for _, k in ctrl.told] == ["straight", "turn", "straight", "turn", "straight", ""]   # "": past the end
    # on an AB line there are no parts: never called
    ab = PartRecorder()
    simulated_run(RunSpec(speed=1.79, duration=3.0, seed=1), ab)
    assert ab.steps > 0 and ab.told == []
