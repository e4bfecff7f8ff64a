"""The comparison report's page in a real browser: Debian's headless Chromium renders ``index.html``,
its tables and figures are there and the figures load; the screenshot is saved beside the page.

``python3 tasks.py test`` installs Chromium when ``/usr/bin/chromium`` is missing; without it this test
fails and says how to install it (it is never skipped).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from hil.bench.runs.report import write_report

CHROMIUM = Path("/usr/bin/chromium")
#: Appended to a copy of the page: after every image loaded, their widths in pixels on ``<body data-images>``.
PROBE = ("<script>window.addEventListener('load', () => { document.body.dataset.images = "
         "[...document.images].map(i => i.complete ? i.naturalWidth : 0).join(','); });</script>")


def _result(ctrl: str, imp: str, speed: float, seed: int, bias: float, sigma: float) -> dict:
    """One pass's summary as a campaign returns it (m, ms), with a short trace for Figure 12."""
    t = [0.25 * k for k in range(80)]
    return {"controller": ctrl, "implement": imp, "speed": speed, "seed": seed, "engaged_fraction": 1.0,
            "disengagements": 0, "deadline_misses": 0, "loop_time_ms_p99": 0.5, "loop_time_ms_max": 1.0,
            "measured_bias_m": bias, "measured_sigma_m": sigma, "true_bias_m": bias, "true_sigma_m": sigma,
            "samples_in_statistics": 1100,
            "trace": {"t": t, "along": [speed * x for x in t],
                      "cross_track": [bias + sigma * (-1) ** k for k in range(80)], "engaged": [1] * 80}}


def _chromium(tmp: Path, *args: str) -> subprocess.CompletedProcess:
    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} is missing: run `apt-get install chromium` (python3 tasks.py test installs it "
                    "when run as root)")
    profile = tmp / "chromium-profile"
    profile.mkdir(exist_ok=True)
    return subprocess.run([str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                           "--no-first-run", "--disable-background-networking", "--disable-component-update",
                           "--disable-sync", f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_the_comparison_page_renders_in_chromium_with_its_tables_and_figures(tmp_path):
    out = tmp_path / "report"
    sigma = {"robust": 0.022, "oracle": 0.02, "central-lqr": 0.04, "stanley": 0.04}
    rs = [_result(c, imp, v, 0, 0.004 if c == "robust" else 0.0, s * v) for c, s in sigma.items()
          for imp in ("disker", "ripper") for v in (1.79, 2.91)]
    rs.append(_result("mpc", "disker", 1.79, 0, 0.03, 0.05))          # a candidate that misses its targets
    write_report(rs, out, title="HIL comparison")
    page = out / "index.html"
    probe = out / "probe.html"
    probe.write_text(page.read_text().replace("</body>", PROBE + "</body>"))

    done = _chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", probe.as_uri())
    assert done.returncode == 0, done.stderr[-2000:]
    dom = done.stdout
    widths = re.search(r'data-images="([0-9,]*)"', dom)
    assert widths, f"the page's script did not run: {dom[:500]}"
    assert [int(w) > 500 for w in widths.group(1).split(",")] == [True, True], f"figures not loaded: {widths.group(1)}"
    assert dom.count("<table") == 5 + 1 + 2 + 1      # Table 2 per controller, timing, targets (2), provenance
    assert '<nav class="toc"' in dom and '<h2 id="provenance">Provenance</h2>' in dom
    assert '<td class="fail">\u2718 missed</td>' in dom and '<td class="pass">\u2714 met</td>' in dom
    assert "<td>git commit</td>" in dom and "`" not in re.sub(r"<[^>]+>", "", dom.split("</style>")[1])
    assert "17 passes: 5 controller(s), 4 condition(s)" in dom

    shot = out / "report.png"
    done = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1280,2000", page.as_uri())
    assert done.returncode == 0 and shot.stat().st_size > 20_000, done.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    shutil.rmtree(tmp_path / "chromium-profile", ignore_errors=True)


def _page(path: Path) -> str:
    return path.read_text().replace("\n", "")


def test_the_commissioning_page_marks_each_step_and_states_its_provenance(tmp_path):
    from hil.bench.commissioning.report import write_commission_report
    ctrl = tmp_path / "controllers" / "robust.json"
    ctrl.parent.mkdir()
    ctrl.write_text('{"controller": "robust"}\n')
    res = {"tractor": {"name": "heavy-11t", "description": "An 11 t tractor.", "parameters": {}},
           "options": {"hil_seeds": [0, 1, 2], "hil_duration": 40.0},
           "steps": [{"step": "valve", "ok": True, "seconds": 1.5},
                     {"step": "identification", "ok": False, "error": "too few passes", "seconds": 2.0}],
           "designs": {"robust": {"file": str(ctrl), "weights": "auto", "settings": {}}}}
    files = write_commission_report(res, tmp_path)
    assert str(tmp_path / "index.html") in files and (tmp_path / "report.md").is_file()
    page = _page(tmp_path / "index.html")
    assert "<title>Commissioning of heavy-11t</title>" in page and '<nav class="toc"' in page
    assert '<td class="pass">ok</td>' in page and '<td class="fail">FAILED: too few passes</td>' in page
    assert "<td>tractor</td><td>heavy-11t</td>" in page and "<td>seeds</td><td>0, 1, 2</td>" in page
    assert "<td>option hil_duration</td><td>40.0</td>" in page
    assert f"<td>sha256 of {ctrl}</td><td>{hashlib.sha256(ctrl.read_bytes()).hexdigest()}</td>" in page
    assert "<code>robust</code>" in page and "`" not in page.split("</style>")[1]


def test_commissioning_from_logs_writes_its_page(tmp_path):
    from hil.bench.benches.valve import characterise_on_bench
    from hil.bench.runs.sysid import SysidPlan, make_passes
    from hil.commissioning.from_logs import commission_from_logs
    from hil.truth.tractors import resolve_tractor
    from hil.vehicle.commissioning import Commissioning, save_commissioning
    params = resolve_tractor("default").params()
    curve, _ = characterise_on_bench(params, seed=5)
    com = save_commissioning(Commissioning("field tractor", curve, None, notes=""), tmp_path / "commissioning.json")
    for name, log in make_passes(SysidPlan(speeds=(1.0,), implements=("none",), passes=1, duration=8.0, seed=11),
                                 params, valve=curve):
        log.save(tmp_path / "logs" / f"{name}.npz")
    res = commission_from_logs(tmp_path / "logs", com, tmp_path / "out", say=lambda line: None)   # 8 s: too short
    assert str(tmp_path / "out" / "index.html") in res["files"]
    page = _page(tmp_path / "out" / "index.html")
    assert "<title>Commissioning of field tractor from its recorded passes</title>" in page
    assert "1 pass log(s); failed: identification." in page
    assert '<td>identification</td><td class="fail">NO</td>' in page
    assert "<td>option acceptance</td><td>refuse</td>" in page and "<td>tractor</td><td>field tractor</td>" in page


def test_the_field_comparison_writes_its_page(tmp_path):
    from gnss.curve import ArcPath
    from gnss.field import Field
    from gnss.field_io import field_to_dict
    from hil.bench.fields.runs import compare_fields
    from hil.truth.conditions import condition_for
    field = tmp_path / "hairpin.json"
    field.write_text(json.dumps(field_to_dict(Field("hairpin", ArcPath((0, 0), 0.0, [(20.0, 0.0)]), 3.0, 2))))
    out = tmp_path / "cmp"
    rep = compare_fields(out, ["kinematic"], [str(field)], [condition_for("none", 1.79)], seeds=(0,), workers=1)
    assert str(out / "index.html") in rep["files"]
    page = _page(out / "index.html")
    assert '<h2 id="runs">Runs</h2>' in page and '<h2 id="figures">Figures</h2>' in page
    assert "<td>hairpin</td><td>kinematic</td>" in page and page.count("<img ") == 3
    assert f"<td>sha256 of {field}</td><td>{hashlib.sha256(field.read_bytes()).hexdigest()}</td>" in page


def test_the_comparison_page_states_the_campaign_it_came_from(tmp_path):
    from hil.truth.tractors import resolve_tractor
    ctrl = tmp_path / "robust.json"
    ctrl.write_text('{"controller": "robust"}\n')
    ident = {"controllers": [str(ctrl), "oracle"], "seeds": [3, 4], "duration": 20.0, "bridge": "hc11",
             "conditions": [["disker", 1.79]], "params": resolve_tractor("heavy-11t").params().to_dict(),
             "controller_files": {str(ctrl): hashlib.sha256(ctrl.read_bytes()).hexdigest()}}
    rs = [_result(c, "disker", 1.79, s, 0.0, 0.03) for c in ("robust", "oracle") for s in (3, 4)]
    write_report(rs, tmp_path / "report", extra={"campaign": ident})
    page = _page(tmp_path / "report" / "index.html")
    assert "<td>tractor</td><td>heavy-11t</td>" in page and "<td>seeds</td><td>3, 4</td>" in page
    assert f"<td>sha256 of {ctrl}</td><td>{ident['controller_files'][str(ctrl)]}</td>" in page
    assert "<td>option conditions</td><td>disker 1.79 m/s</td>" in page
    assert "<td>option duration [s]</td><td>20.0</td>" in page
