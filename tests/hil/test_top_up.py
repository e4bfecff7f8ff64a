"""An implement added to a commissioned tractor later (hil.commissioning.top_up, ``hil commission --top-up``):
the laws of the implements commissioned before stay bit for bit, the new implement's controllers are
certified on its own models, and every refusal is one line before anything is written. The logs and the
commissioning file are made on the bench beforehand, as a tractor's runtime would record them."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.cli import main as hil_main
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.commissioning.from_logs import CommissioningError, LogOptions, driving_seconds
from hil.commissioning.html import file_sha256
from hil.commissioning.model_choice import orders_of
from hil.bench.commissioning.recipe import CommissionOptions, options_dict
from hil.commissioning.top_up import TopUpOptions, _options, top_up
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, load_commissioning, save_commissioning
from hil.vehicle.controllers import vehicle_controller
from identification.passlog import PassLog

REPORTS = ("result.json", "report.md", "index.html")


def _tree(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder``, by its path relative to it."""
    return {str(f.relative_to(folder)): hashlib.sha256(f.read_bytes()).hexdigest()
            for f in sorted(folder.rglob("*")) if f.is_file()}


def _recorded(root: Path, duration: float, speeds: tuple[float, ...]) -> tuple[Path, dict[str, list]]:
    """The default tractor's commissioning file and passes of none, disker and ripper (two per speed)."""
    params = resolve_tractor("default").params()
    curve, _ = characterise_on_bench(params, seed=5)
    com = save_commissioning(Commissioning("field tractor", curve, None, notes="valve test"),
                             root / "commissioning.json")
    plan = SysidPlan(speeds=speeds, implements=("none", "disker", "ripper"), passes=2, duration=duration, seed=11)
    by_imp: dict[str, list] = {}
    for name, log in make_passes(plan, params, valve=curve):
        by_imp.setdefault(str(log.meta["implement"]), []).append((name, log))
    return com, by_imp


def _save(logs: Path, passes: list) -> None:
    for name, log in passes:
        log.save(logs / f"{name}.npz")


@pytest.mark.slow
def test_a_top_up_with_a_new_implement_keeps_the_existing_implements_laws_bit_for_bit(tmp_path, capsys):
    com, by_imp = _recorded(tmp_path, 40.0, (1.0, 2.24))
    logs, out = tmp_path / "logs", tmp_path / "out"
    _save(logs, by_imp["none"] + by_imp["disker"])
    assert hil_main(["commission", "--logs", str(logs), "--commissioning", str(com), "--out", str(out),
                     "--acceptance", "warn", "--quiet"]) == 0         # the top-up reads acceptance warn back
    before = _tree(out)
    first = json.loads((out / "result.json").read_text())
    assert {"central-lqr", "robust", "mpc"} <= set(first["designs"]), first["steps"]

    _save(logs, by_imp["ripper"])                    # the ripper's passes, recorded after the commissioning
    capsys.readouterr()
    assert hil_main(["commission", "--logs", str(logs), "--commissioning", str(com), "--out", str(out),
                     "--top-up", "ripper", "--quiet"]) == 0
    assert "driving in the logs: 2.7 min" in capsys.readouterr().out          # the ripper's 4 passes of 40 s
    after = _tree(out)
    kept = {k: v for k, v in before.items() if k not in REPORTS}
    assert kept and {k: after.get(k) for k in kept} == kept                  # every other file byte for byte
    new = sorted(set(after) - set(before))
    assert "controllers/ripper/robust.json" in new and "controllers/ripper/mpc.json" in new
    assert all(k.startswith(("controllers/ripper/", "models/ripper/")) for k in new), new

    res = json.loads((out / "result.json").read_text())
    assert {k: v for k, v in res.items() if k != "top_ups"} == first              # the commissioning's record kept
    (top,) = res["top_ups"]
    assert top["implement"] == "ripper" and top["driving_s"]["total"] == pytest.approx(160.0, abs=1.0)
    assert top["driving_s"]["total"] <= 600.0 and 0 < top["compute_s"] <= 180.0
    choice = top["designs"]["robust"]["model_choice"]          # the commissioning's choice of models, made again
    if orders_of(out / "models" / "ripper") == {4}:
        assert choice == {"kept": "identified", "why": "the local models are of order 4"}
    else:                                                        # its order-4 models beside the ripper's own
        assert orders_of(out / "models" / "ripper" / "order4") == {4} and choice["kept"] in ("identified",
                                                                                             "order-4 models")
    assert sorted(str(Path(f).relative_to(out)) for f in top["files"]) == new
    for name in ("robust", "mpc"):
        file = out / "controllers" / "ripper" / f"{name}.json"
        vehicle_controller(str(file))                                             # hil drive's loader
        cert = json.loads(file.read_text())["certificate"]
        assert cert["passed"] and top["designs"][name]["result"]["certificate"]["passed"]
        local = sorted(m["name"] for m in cert["models"] if m["name"].startswith("local_"))
        assert local == ["local_ripper_11th", "local_ripper_5th"]              # the ripper's models, both speeds
        assert not any("none" in m["name"] or "disker" in m["name"] for m in cert["models"])
    # the designer's settings are the commissioning's
    for key in ("command_limit_rad_s", "integral", "disturbance_estimate"):
        assert top["designs"]["robust"]["settings"][key] == first["designs"]["robust"]["settings"][key]
    report = (out / "report.md").read_text()
    assert "## Implement added later: ripper" in report and "4 pass logs, 2.7 min of driving" in report
    assert "Implement added later: ripper" in (out / "index.html").read_text()

    # the ripper is commissioned now: a second top-up of it is refused, nothing written
    now = _tree(out)
    with pytest.raises(CommissioningError, match="the ripper is commissioned in .* already"):
        top_up(logs, com, out, TopUpOptions("ripper"))
    assert _tree(out) == now


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> tuple[Path, Path, dict[str, list]]:
    """A commissioning's result.json as commissioning from logs records it (its logs: none's passes), the
    commissioning file and short passes of each implement (no identification: refusals come before it)."""
    root = tmp_path_factory.mktemp("small")
    com, by_imp = _recorded(root, 20.0, (1.0,))
    logs = root / "logs"
    _save(logs, by_imp["none"])
    files = sorted(logs.glob("*.npz"))
    out = root / "out"
    (out / "controllers").mkdir(parents=True)
    valve = json.loads(com.read_text())["valve"]
    res = {"tractor": "field tractor", "logs": [str(f) for f in files], "commissioning": str(com),
           "options": {**asdict(LogOptions()), "acceptance": "warn"}, "valve": valve,
           "driving_s": driving_seconds([PassLog.load(f) for f in files]),
           "log_sha256": {f.name: file_sha256(f) for f in files}, "designs": {}, "steps": []}
    (out / "result.json").write_text(json.dumps(res))
    return com, out, by_imp


def _refused(argv: list[str], capsys) -> str:
    assert hil_main(["commission", *argv, "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hil commission: error:"), err
    return err[0]


def test_a_top_up_is_refused_in_one_line_before_anything_is_written(small, tmp_path, capsys):
    com, out, by_imp = small
    logs = tmp_path / "logs"
    _save(logs, by_imp["none"] + by_imp["ripper"])
    args = ["--logs", str(logs), "--commissioning", str(com), "--top-up"]
    before = _tree(out)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "holds no commissioning (result.json and controllers/)" in _refused(
        ["--logs", str(logs), "--commissioning", str(com), "--out", str(empty), "--top-up", "ripper"], capsys)
    assert not any(empty.iterdir())
    assert "the none is commissioned in" in _refused([*args, "none", "--out", str(out)], capsys)
    assert "no pass log of the disker in" in _refused([*args, "disker", "--out", str(out)], capsys)
    _save(logs, by_imp["disker"][:1])                       # a disker pass the commissioning was not made from
    line = _refused([*args, "ripper", "--out", str(out)], capsys)
    assert "pass logs of other implements newer than the commissioning" in line and by_imp["disker"][0][0] in line
    (logs / f"{by_imp['disker'][0][0]}.npz").unlink()
    name, log = by_imp["none"][0]                           # a none pass recorded again since the commissioning
    PassLog(times=dict(log.times), channels=dict(log.channels), meta={**log.meta, "drive": 2}).save(
        logs / f"{name}.npz")
    assert f"({name}.npz)" in _refused([*args, "ripper", "--out", str(out)], capsys)
    _save(logs, by_imp["none"][:1])
    other = save_commissioning(Commissioning("another tractor", load_commissioning(com).valve, None),
                               tmp_path / "other.json")
    assert "is not the commissioning file" in _refused(
        ["--logs", str(logs), "--commissioning", str(other), "--out", str(out), "--top-up", "ripper"], capsys)
    assert "--weights: a top-up designs with the settings of the commissioning" in _refused(
        [*args, "ripper", "--out", str(out), "--weights", "default"], capsys)
    assert "--top-up go with --logs" in _refused(["--tractor", "default", "--out", str(out), "--top-up", "ripper"],
                                                 capsys)
    assert _tree(out) == before and not (out / "models").exists()


def test_a_top_up_designs_with_the_commissionings_fastest_estimate_scale(tmp_path):
    """The fastest band law's estimate scale is read back from the commissioning's result.json, from logs or from
    the bench, and an older commissioning without it keeps full gain, as it was designed."""
    logs = {"options": {**asdict(LogOptions()), "fastest_estimate_scale": 0.7}}
    assert _options(logs, tmp_path / "result.json").fastest_estimate_scale == 0.7
    bench = {"options": json.loads(json.dumps(options_dict(CommissionOptions(fastest_estimate_scale=0.5))))}
    assert _options(bench, tmp_path / "result.json").fastest_estimate_scale == 0.5
    older = {k: v for k, v in asdict(LogOptions()).items() if k != "fastest_estimate_scale"}
    assert _options({"options": older}, tmp_path / "result.json").fastest_estimate_scale == 1.0
