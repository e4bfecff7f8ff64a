"""An MPC file's prediction models by speed band (design/files/prediction_schedule.py): written by the design,
checked on every read (a tampered band refused), run by the controller on one state with the latched band's
QP, a band whose law holds the next slower speed's models too reaching down towards it, and a band whose law
is not stable on its own band's models left to the central law."""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.core.errors import ControllerFileError
from design.core.speed_latch import DWELL_S
from design.core.weights import OutputWeights
from design.laws.controller import Measurement
from design.laws.disturbance import DisturbanceSpec
from design.files.mpc import read_mpc_file
from design.files.prediction_schedule import RECORD
from design.mpc import MPCLimits, MPCWeights, SolverSettings
from design.synthesis.mpc_design import MPCSpec, design_mpc, with_prediction_schedule

from design_family import rewrite, tractor_model

SPEEDS = (1.0, 1.79, 2.91)
SPEC = MPCSpec(horizon=20, limits=MPCLimits(0.3, 0.1), settings=SolverSettings(time_budget=1.0),
               disturbance=DisturbanceSpec())


def local(speed: float, implement: str, authority: float, **kw):
    """A local model as identification names it: one condition with its implement and nominal speed."""
    return tractor_model(speed, authority, name=f"local_{implement}_{speed:g}", **kw).with_meta(
        conditions=[{"implement": implement, "nominal_speed": speed}])


@pytest.fixture(scope="module")
def scheduled():
    models = [local(v, imp, a) for v in SPEEDS for imp, a in (("none", 1.0), ("disker", 0.7))]
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    return with_prediction_schedule(design_mpc(central, models, SPEC), models), models


@pytest.fixture()
def saved(scheduled, tmp_path):
    return scheduled[0].file.save(tmp_path / "mpc.json")


def test_each_design_speed_gets_its_band_and_its_none_model(scheduled, saved):
    res, _ = scheduled
    rec = res.file.design[RECORD]
    # the 1.79 and 2.91 m/s laws hold the next slower speed's models too: each runs down to a quarter of the way
    # above that speed (1.00 + 0.25 x 0.79, 1.79 + 0.25 x 1.12), not half-way
    assert rec["bands"] == [[0.0, pytest.approx(1.1975)], [pytest.approx(1.1975), pytest.approx(2.07)],
                            [pytest.approx(2.07), None]] and rec["left_out"] == []
    assert [law["model"]["name"] for law in rec["laws"]] == ["local_none_1", "local_none_1.79", "local_none_2.91"]
    slower = {1.0: None, 1.79: 1.0, 2.91: 1.79}
    for law, row, v in zip(rec["laws"], res.prediction_schedule["bands"], SPEEDS):
        # certified on exactly its band's models, every implement, and the slower speed's it reaches down to
        below = [] if slower[v] is None else [f"local_none_{slower[v]:g}", f"local_disker_{slower[v]:g}"]
        names = [f"local_none_{v:g}", f"local_disker_{v:g}", *below]
        assert [r["name"] for r in law["certificate"]["models"]] == names == row["models"]
        assert [r["name"] for r in law["band_models"]] == names
        assert law["certificate"]["passed"] and law["certificate_off"]["passed"]
        assert {r["speed"] for r in law["neighbours"]} == set(SPEEDS) - {v, slower[v]}
        if slower[v] is not None:
            assert row["reach_down"]["speed"] == slower[v] and row["reach_down"]["min_disk_margin"] >= 0.6
            assert min(c["disk_margin"] for c in law["certificate"]["models"][2:]) == \
                pytest.approx(row["reach_down"]["min_disk_margin"])
        else:
            assert "reach_down" not in row
    spec = read_mpc_file(saved)
    assert spec.to_dict() == json.loads(saved.read_text())
    assert spec.prediction_schedule.bands == ((0.0, pytest.approx(1.1975)), (pytest.approx(1.1975),
                                              pytest.approx(2.07)), (pytest.approx(2.07), float("inf")))


def _step(ctrl, t: float, v: float) -> float:
    return ctrl.step(Measurement(t, 0.01, 0.002, 0.0, v))


def test_the_controller_switches_band_past_the_hysteresis_and_runs_the_band_law(saved):
    spec = read_mpc_file(saved)
    ctrl = spec.controller(approach=False)
    t = 0.0
    for _ in range(30):
        _step(ctrl, t, 1.79)
        t += 0.05
    assert ctrl.band == 1
    for _ in range(40):                               # just past the edge at 2.07 m/s, inside the hysteresis
        _step(ctrl, t, 2.09)
        t += 0.05
    assert ctrl.band == 1 and ctrl.latch.switches == 0
    _step(ctrl, t, 2.17)                              # 0.1 m/s inside the band, after the dwell: band 2's QP
    assert ctrl.band == 2 and ctrl.latch.switches == 1 and ctrl.backend is ctrl.backends[3]
    assert ctrl.last.fallback is False and DWELL_S <= 40 * 0.05
    # the latched band's QP gives its own unconstrained law's first move from a small state
    laws, central = spec.band_laws(), spec.law()
    z = np.zeros(ctrl.problem.nz)
    z[ctrl.problem.layout.output_slot(0)] = (1e-3, 5e-4, 1e-3)
    k2 = np.array(spec.design[RECORD]["laws"][2]["unconstrained_gain"])
    k0 = np.array(spec.design["unconstrained_gain"])
    assert ctrl.solve_qp(z).u0 == pytest.approx(float(k2[0] @ z), rel=1e-4)
    assert abs(float(k0[0] @ z) - float(k2[0] @ z)) > 1e-2 * abs(float(k2[0] @ z))   # not the central law's
    # from an engage at 2.91 m/s the first command is band 2's law on the measured state (the window filled
    # with the present outputs), as its compensator gives it
    fresh = spec.controller(approach=False)
    m = Measurement(0.0, 0.01, 0.002, 0.0, 2.91)
    y = fresh.outputs(m)
    assert fresh.step(m) == pytest.approx(float(laws[2].Dc[0] @ y + laws[2].Cc[0] @ (laws[2].X0 @ y)), rel=1e-4)
    assert fresh.band == 2 and central is not None


def test_a_tampered_band_is_refused(saved):
    def refused(edit, match):
        body = json.loads(saved.read_text())
        path = saved.with_name("t.json")
        path.write_text(json.dumps(body))
        rewrite(path, edit)
        with pytest.raises(ControllerFileError, match=match):
            read_mpc_file(path)

    def gain(b):
        g = b["design"][RECORD]["laws"][2]["unconstrained_gain"]
        g[0][0] *= 1.001
    refused(gain, "band 2: the recorded unconstrained gain differs")

    def swap(b):                                      # band 0 runs band 2's law: its models are not band 0's
        laws = b["design"][RECORD]["laws"]
        laws[0], laws[2] = laws[2], laws[0]
    refused(swap, r"band 0 \(0-1.1975 m/s\): model 'local_none_2.91' was identified at 2.91 m/s, outside the band")

    def uncertified(b):                               # a band's model taken out of its law's certificate
        b["design"][RECORD]["laws"][1]["certificate"]["models"].pop()
    refused(uncertified, r"band 1 \(1.1975-2.07 m/s\): its certificate was made on 3 models, not exactly the "
                         r"band's 4")

    def two_below(b):                                 # a band listing the models of two slower design speeds
        law0, law2 = b["design"][RECORD]["laws"][0], b["design"][RECORD]["laws"][2]
        law2["band_models"] += law0["band_models"]
    refused(two_below, r"band 2 \(2.07-inf m/s\): its models were identified at \[1.0, 1.79, 2.91\] m/s")

    def none_inside(b):                               # a band with none of its own models
        law = b["design"][RECORD]["laws"][2]
        law["band_models"] = [r for r in law["band_models"] if r["speed"] == 1.79]
    refused(none_inside, r"band 2 \(2.07-inf m/s\): its models were identified at \[1.79\] m/s")

    def overlap(b):
        b["design"][RECORD]["bands"][1] = [1.0, 2.35]
    refused(overlap, "prediction-schedule bands overlap")

    def foreign(b):                                   # a prediction model that is none of the band's models
        law = b["design"][RECORD]["laws"][1]
        law["band_models"] = [r for r in law["band_models"] if r["name"] != "local_none_1.79"]
    refused(foreign, "its prediction model 'local_none_1.79' is not one of the band's models")


def test_a_band_whose_law_its_own_models_do_not_hold_is_left_to_the_central_law():
    """A slow valve on the disker at 2.91 m/s (0.8 s lag): the central law, predicting with a slow model, holds
    it; the band's law predicting with the fast none model at the same weights does not."""
    models = [local(1.0, "none", 1.0), local(1.0, "disker", 0.7), local(2.91, "none", 1.0),
              local(2.91, "disker", 1.0, tau=0.8)]
    central = tractor_model(2.91, name="central", tau=0.8).with_meta(kind="central")
    spec = MPCSpec(horizon=20, limits=MPCLimits(0.3, 0.1), settings=SolverSettings(time_budget=1.0), past=2,
                   weights=MPCWeights(OutputWeights()))
    res = with_prediction_schedule(design_mpc(central, models, spec), models)
    rec = res.file.design[RECORD]
    assert rec["bands"] == [[0.0, 1.955]]
    assert [x["speed"] for x in rec["left_out"]] == [2.91]
    assert "not stable on local_disker_2.91" in rec["left_out"][0]["reason"]
    assert res.prediction_schedule["left_out"] == rec["left_out"]
    ctrl = res.file.controller(approach=False)
    _step(ctrl, 0.0, 2.91)
    assert ctrl.band is None                          # the central law runs where the band was left out


def test_design_mpc_adds_the_schedule_unless_told_not_to(scheduled, tmp_path, capsys):
    from design.cli import main as design_main
    _, models = scheduled
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in [central, *models]]
    common = ["mpc", "--models", *paths, "--horizon", "20", "--time-budget-ms", "1000"]
    assert design_main([*common, "--out", str(tmp_path / "on.json")]) == 0
    text = capsys.readouterr().out
    assert "2.07- m/s: local_none_2.91, worst local_" in text and "on the other bands' models stable" in text
    assert [law["model"]["name"] for law in read_mpc_file(tmp_path / "on.json").design[RECORD]["laws"]] == \
        ["local_none_1", "local_none_1.79", "local_none_2.91"]
    assert design_main([*common, "--prediction-schedule", "off", "--out", str(tmp_path / "off.json")]) == 0
    capsys.readouterr()
    off = read_mpc_file(tmp_path / "off.json")
    assert RECORD not in off.design and off.prediction_schedule is None and off.controller().bands == ()


def test_a_band_whose_law_the_sensors_noise_would_hold_at_the_rate_limit_is_left_to_the_central_law(scheduled):
    res, models = scheduled
    assert all(b["noise_gain"] >= 1.4 / 2.6 for b in res.prediction_schedule["bands"])   # the receiver's noise: kept
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    # a metre of position noise: at 1.00 m/s every band's law would sit at the rate limit
    noisy = with_prediction_schedule(design_mpc(central, models, SPEC), models, noise=(1.0, 0.0175, 0.005))
    left = noisy.prediction_schedule["left_out"]
    assert 1.0 in [x["speed"] for x in left]
    reason = next(x["reason"] for x in left if x["speed"] == 1.0)
    assert reason.startswith("the sensors' noise alone drives its command to") and "below the disk margin" in reason


def test_a_band_whose_law_is_much_noisier_than_the_central_law_on_its_models_is_left_to_it(monkeypatch):
    """A slow valve at 1.00 m/s (0.5 s lag, both implements): the band's law, predicting with it, answers the
    sensors' noise with a command 2.6 times the central law's on the band's models; the noise is small enough
    for every law to pass the noise check's floor, so only the comparison with the central law leaves it out."""
    import design.synthesis.mpc_design as mpc_design

    models = [local(v, imp, a, tau=0.5 if v == 1.0 else 0.1) for v in SPEEDS for imp, a in (("none", 1.0),
                                                                                             ("disker", 0.7))]
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    base = design_mpc(central, models, SPEC)
    quiet = (0.001, 1e-4, 5e-4)
    res = with_prediction_schedule(base, models, noise=quiet)
    rec = res.file.design[RECORD]
    assert rec["bands"] == [[1.395, pytest.approx(2.07)], [pytest.approx(2.07), None]]
    assert [x["speed"] for x in rec["left_out"]] == [1.0]
    # the 1.79 m/s law does not hold the slow valve's 1.00 m/s models with the disk margin: it stops half-way
    down = res.prediction_schedule["bands"][0]["reach_down"]
    assert down["speed"] == 1.0 and "low_mps" not in down
    assert down["refused"].startswith("its disk margin on local_") and down["refused"].endswith("below 0.6")
    assert float(down["refused"].split(" is ")[1].split(",")[0]) < 0.6
    reason = rec["left_out"][0]["reason"]
    assert "times the central law's" in reason and f"at most {mpc_design.NOISE_RATIO:g} times" in reason
    ratio = float(reason.split(" times the central law's")[0].rsplit(" ", 1)[1])
    assert ratio > mpc_design.NOISE_RATIO
    assert all(b["noise_over_central"] <= mpc_design.NOISE_RATIO for b in res.prediction_schedule["bands"])
    ctrl = res.file.controller(approach=False)
    _step(ctrl, 0.0, 1.0)
    assert ctrl.band is None                          # the central law runs at 1.00 m/s
    monkeypatch.setattr(mpc_design, "NOISE_RATIO", float("inf"))      # without the comparison the band is kept
    kept = with_prediction_schedule(base, models, noise=quiet)
    assert kept.file.design[RECORD]["bands"][0] == [0.0, 1.395]
    assert kept.prediction_schedule["bands"][0]["noise_over_central"] == pytest.approx(ratio, abs=0.01)
