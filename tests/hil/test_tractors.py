"""Tractor files, the named family and the random generator."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import pytest

from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.truth.tractors import (
    RANDOM_RANGES,
    Tractor,
    builtin_tractors,
    load_tractor,
    random_tractor,
    resolve_tractor,
    save_tractor,
    tractors_markdown,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "tractors.md"


def _file(tmp_path: Path, d: dict) -> Path:
    p = tmp_path / "t.json"
    p.write_text(json.dumps(d))
    return p


@pytest.mark.parametrize("tractor", [*builtin_tractors().values(), *(random_tractor(s) for s in range(5))],
                         ids=lambda t: t.name)
def test_a_tractor_file_round_trips(tractor: Tractor, tmp_path: Path) -> None:
    back = load_tractor(save_tractor(tractor, tmp_path / f"{tractor.name}.json"))
    assert back == tractor
    assert back.params() == tractor.params()
    assert Tractor.from_dict(json.loads(json.dumps(tractor.to_dict()))) == tractor
    # what the file says is what the simulator gets
    p = back.params()
    for key, value in tractor.overrides().items():
        group, _, name = key.partition(".")
        assert getattr(getattr(p, group), name) == value


def test_the_default_tractor_stays_the_calibrated_one() -> None:
    assert resolve_tractor("default").params() == SimParams()
    assert resolve_tractor("default").parameters == {}


def test_the_issues_two_tractors_are_in_the_family() -> None:
    heavy = resolve_tractor("heavy-11t").params()
    assert heavy.vehicle.mass == 11000 and heavy.vehicle.wheelbase == 3.1
    assert (heavy.steering.lag, heavy.steering.deadband, heavy.steering.max_rate) == (0.15, 0.12, 0.28)
    assert heavy.gps.position_latency == 0.15 and heavy.vehicle.antenna_ahead_of_cg == 0.5
    worn, d = resolve_tractor("worn-valve").params(), SimParams()
    assert worn.steering.deadband > d.steering.deadband
    assert worn.steering.flow_exponent > d.steering.flow_exponent
    assert abs(1 - worn.steering.right_gain) > abs(1 - d.steering.right_gain)
    assert worn.sensor.noise > d.sensor.noise
    assert worn.gps.position_latency > d.gps.position_latency


@pytest.mark.parametrize("group,name,value,range_text", [
    ("vehicle", "mass", -5.0, "(0, 40000]"),
    ("vehicle", "mass", 1e308, "(0, 40000]"),
    ("steering", "deadband", 0.95, "[0, 0.9]"),
    ("sensor", "cubic", 0.5, "[-0.3, 0.3]"),
    ("gps", "position_latency", -0.1, "[0, 1]"),
])
def test_out_of_range_values_are_refused_with_the_range(tmp_path: Path, group: str, name: str, value: float,
                                                         range_text: str) -> None:
    d = resolve_tractor("heavy-11t").to_dict()
    d["parameters"].setdefault(group, {})[name] = value
    with pytest.raises(SimulatorConfigError, match=rf"{group}\.{name} = .* outside its range " + re.escape(range_text)):
        load_tractor(_file(tmp_path, d))


@pytest.mark.parametrize("mutate,message", [
    (lambda d: d["parameters"]["steering"].update(deadbnd=0.1), r"unknown parameter steering\.deadbnd"),
    (lambda d: d["parameters"].update(engine={"power": 1.0}), r"unknown parameter group 'engine'"),
    (lambda d: d.update(colour="green"), r"unknown key\(s\) \['colour'\]"),
    (lambda d: d.update(version=2), r"not a tractor file"),
    (lambda d: d["parameters"]["steering"].update(lag="fast"), r"steering\.lag must be a finite number"),
    (lambda d: d["parameters"]["vehicle"].update(cg_to_front_axle=4.0), r"cg_to_front_axle .* shorter than"),
    (lambda d: d.pop("name"), r"missing key"),
])
def test_bad_tractor_files_are_refused(tmp_path: Path, mutate, message: str) -> None:
    d = resolve_tractor("heavy-11t").to_dict()
    mutate(d)
    with pytest.raises(SimulatorConfigError, match=message):
        load_tractor(_file(tmp_path, d))


def test_unknown_names_and_missing_files_say_what_exists(tmp_path: Path) -> None:
    with pytest.raises(SimulatorConfigError, match="heavy-11t"):
        resolve_tractor("heavy")
    with pytest.raises(SimulatorConfigError, match="does not exist"):
        resolve_tractor(str(tmp_path / "none.json"))


def test_random_tractors_are_seeded_and_within_their_documented_ranges() -> None:
    assert random_tractor(7) == random_tractor(7)
    assert random_tractor(7).parameters != random_tractor(8).parameters
    g = 9.80665
    for seed in range(40):
        p = random_tractor(seed).params()   # valid simulator parameters
        v, s = p.vehicle, p.steering
        r = RANDOM_RANGES
        tol = 1e-3
        assert r["mass"].lo - tol <= v.mass <= r["mass"].hi + tol
        assert r["wheelbase"].lo - tol <= v.wheelbase <= r["wheelbase"].hi + tol
        share = 1 - v.cg_to_front_axle / v.wheelbase
        assert r["front_load_fraction"].lo - tol <= share <= r["front_load_fraction"].hi + tol
        gyration = (v.yaw_inertia / v.mass) ** 0.5 / v.wheelbase
        assert r["gyration"].lo - tol <= gyration <= r["gyration"].hi + tol
        cf = v.front_cornering_stiffness / (v.mass * g * share)
        assert r["front_cornering_coefficient"].lo - tol <= cf <= r["front_cornering_coefficient"].hi + tol
        for key, value in (("max_rate", s.max_rate), ("lag", s.lag), ("deadband", s.deadband),
                           ("flow_exponent", s.flow_exponent), ("right_gain", s.right_gain),
                           ("cubic", p.sensor.cubic), ("sensor_noise", p.sensor.noise),
                           ("position_latency", p.gps.position_latency),
                           ("attitude_latency", p.gps.attitude_latency),
                           ("antenna_ahead_of_cg", v.antenna_ahead_of_cg)):
            assert r[key].lo - tol <= value <= r[key].hi + tol, (seed, key, value)
        # the calibrated disturbances and GPS noise are left as calibrated
        assert p.field == SimParams().field and p.disker == SimParams().disker
        assert p.gps.position_noise == SimParams().gps.position_noise


def test_the_default_tractor_lies_inside_the_generators_ranges() -> None:
    d = SimParams()
    for key, value in (("mass", d.vehicle.mass), ("wheelbase", d.vehicle.wheelbase),
                       ("max_rate", d.steering.max_rate), ("lag", d.steering.lag),
                       ("deadband", d.steering.deadband), ("flow_exponent", d.steering.flow_exponent),
                       ("right_gain", d.steering.right_gain), ("position_latency", d.gps.position_latency)):
        assert RANDOM_RANGES[key].lo <= value <= RANDOM_RANGES[key].hi, key


def test_the_tractors_document_is_generated_from_the_data() -> None:
    assert DOC.read_text() == tractors_markdown(), "regenerate: hil tractors --markdown > docs/tractors.md"


def test_tractor_is_frozen() -> None:
    t = resolve_tractor("worn-valve")
    with pytest.raises(dataclasses.FrozenInstanceError):
        t.name = "x"  # type: ignore[misc]


def test_the_bench_commands_read_a_tractor_with_set_on_top(tmp_path: Path, capsys) -> None:
    from hil.bench.cli import main
    from identification.passlog import PassLog
    assert main(["params", "--tractor", "heavy-11t", "--set", "steering.lag=0.2", "--json"]) == 0
    rows = {r["name"]: r["value"] for r in json.loads(capsys.readouterr().out)["parameters"]}
    assert rows["vehicle.mass"] == 11000 and rows["steering.lag"] == 0.2 and rows["steering.deadband"] == 0.12
    f = save_tractor(random_tractor(5), tmp_path / "r5.json")
    assert main(["sysid", "--tractor", str(f), "--out", str(tmp_path / "logs"), "--speeds", "1.0", "--implements",
                 "none", "--passes", "1", "--duration", "5", "--quiet", "--json"]) == 0
    log = PassLog.load(json.loads(capsys.readouterr().out)["files"][0])
    assert log.meta["simulator"] == random_tractor(5).params().to_dict()
    assert main(["run", "--tractor", "no-such", "--controller", "kinematic", "--out", str(tmp_path / "r")]) == 1
    assert "unknown tractor 'no-such'" in capsys.readouterr().err


class _ConstantRate:
    """A controller that asks for one steering rate every cycle (rad/s)."""

    name = "constant"
    dt = 0.05

    def __init__(self, rate: float) -> None:
        self.rate = rate

    def reset(self) -> None:
        pass

    def step(self, m) -> float:
        return self.rate

    def estimate(self) -> tuple[float, ...]:
        return ()


@pytest.mark.parametrize("name", ["default", "heavy-11t", "compact-4t", "random-13"])
def test_the_bridge_gives_the_duty_the_passes_and_the_oracle_assume(name: str) -> None:
    # The identification passes (hil.bench.runs.sysid) and the oracle turn a rate into a duty with
    # nominal_duty (full duty = the tractor's max_rate); the HC11 firmware of the HIL runs must do the
    # same, or the two see different valves (its full scale was 0.35 rad/s on every tractor).
    from hil.bench.runs.run import RunSpec, simulated_run
    from hil.truth.steering import nominal_duty
    st = resolve_tractor(name).params().steering
    log = simulated_run(RunSpec(implement="none", speed=1.0, duration=2.0, seed=0), _ConstantRate(0.02),
                        resolve_tractor(name).params())
    fw = log.meta["firmware"]
    assert fw["engaged"] and fw["commands_applied"] > 10
    assert fw["duty"] == pytest.approx(float(nominal_duty(0.02, st)), abs=2e-4)   # 1e-4 rad/s command steps
