"""The comparison report's page in a real browser: Debian's headless Chromium renders ``index.html``,
its tables and figures are there and the figures load; the screenshot is saved beside the page.

``python3 tasks.py test`` installs Chromium when ``/usr/bin/chromium`` is missing; without it this test
fails and says how to install it (it is never skipped).
"""

from __future__ import annotations

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
            "trace": {"t": t, "along": [speed * x for x in t], "cross_track": [bias + sigma * (-1) ** k for k in range(80)],
                      "engaged": [1] * 80}}


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
