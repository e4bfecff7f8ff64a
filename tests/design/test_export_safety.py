"""What a controller file can put into exported code, and outputs that are whole or untouched.

Text of the file that reaches an export (the outputs' units) must match a strict pattern:
the loader and every export format refuse anything else in one line. Exports, signed files
and designed files are written atomically: when the write fails part-way (here: a file-size
limit set with ``setrlimit`` in a child process, so the real write fails with EFBIG) the old
output is left byte for byte and no temporary file or directory is left behind; a file of the
old fixed temporary name (``*.part``) is never written through.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from design.core.errors import ControllerFileError
from design.export.formats import export_controller
from design.export.c_code import DATA_HEADER, OWNED, VECTORS
from design.files.binding import bind
from design.files.envelope import seal
from design.files.load import load_controller, sign_file
from design.files.signature import keygen, load_private_key
from design.synthesis.robust import RobustSpec, design_lqr, design_robust

from design_family import family, tractor_model

ROOT = Path(__file__).resolve().parents[2]
INJECTIONS = ('s */\n#include "/etc/passwd"\n/* ', "s\nAc,0,0,1e9", "rad s", "s*/x", "m;", "", )


@pytest.fixture(scope="module")
def controllers(tmp_path_factory):
    d = tmp_path_factory.mktemp("c")
    robust = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True)).file
    lqr, _ = design_lqr(tractor_model(1.79, name="central"), family(speeds=(1.0, 2.0), authorities=(1.0,)))
    return robust.save(d / "robust.json"), lqr.save(d / "lqr.json")


def _with_units(src: Path, dst: Path, units: str) -> Path:
    body = json.loads(src.read_text())
    body["outputs"][0]["units"] = units
    dst.write_text(json.dumps(seal(bind(body))))            # re-certified: only the units check can refuse it
    return dst


@pytest.mark.parametrize("units", INJECTIONS[:-1])
def test_units_that_could_escape_a_comment_or_a_csv_row_are_refused_everywhere(controllers, tmp_path, units):
    p = _with_units(controllers[0], tmp_path / "evil.json", units)
    with pytest.raises(ControllerFileError, match=r"units must be unit symbols joined by \* or /") as err:
        load_controller(p)
    assert "\n" not in str(err.value).replace(repr(units), "")
    for fmt, out in (("c-header", tmp_path / "x.h"), ("csv", tmp_path / "x.csv"), ("c", tmp_path / "c"),
                     ("json", tmp_path / "x.json")):
        with pytest.raises(ControllerFileError, match="units must be"):
            export_controller(p, fmt, out)
        assert not out.exists()


def test_plain_units_are_exported(controllers, tmp_path):
    p = _with_units(controllers[0], tmp_path / "ok.json", "m^-1")
    assert "cross_track/speed [m^-1]" in export_controller(p, "c-header")
    p = _with_units(controllers[0], tmp_path / "none.json", INJECTIONS[-1])
    assert "cross_track/speed []" in export_controller(p, "csv")


def _run_limited(code: str, limit: int) -> subprocess.CompletedProcess:
    """Run ``code`` in a child whose files may not grow past ``limit`` bytes (writes past it fail with EFBIG)."""
    prelude = textwrap.dedent(f"""
        import resource, signal, sys
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
    """)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)


def _snapshot(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


def test_an_export_that_fails_part_way_leaves_the_old_file_whole(controllers, tmp_path):
    formats = ("json", "csv", "c-header")
    d = tmp_path / "out"
    d.mkdir()
    for fmt in formats:
        (d / fmt).write_text(export_controller(controllers[1], fmt))     # an earlier export, of another law
    before = _snapshot(d)
    limit = min(len(export_controller(controllers[0], fmt).encode()) for fmt in formats) // 2
    done = _run_limited(f"""
        from design.export.formats import export_controller
        for fmt in {formats!r}:
            try:
                export_controller({str(controllers[0])!r}, fmt, {str(d)!r} + "/" + fmt)
            except (OSError, ValueError) as exc:
                print("refused:", exc)
    """, limit)
    assert done.stdout.count("refused:") == len(formats), done.stdout + done.stderr
    assert _snapshot(d) == before                                        # old files whole, no temporary left


def test_a_c_export_that_fails_part_way_leaves_the_old_folder_whole(controllers, tmp_path):
    out = tmp_path / "parent" / "c"
    export_controller(controllers[1], "c", out)                          # an earlier export, of another law
    assert {p.name for p in out.iterdir()} == set(OWNED)
    before, siblings = _snapshot(out), sorted(out.parent.iterdir())
    limit = (out / VECTORS).stat().st_size // 2                          # the header fits, the vectors do not
    assert (out / DATA_HEADER).stat().st_size < limit
    done = _run_limited(f"""
        from design.export.formats import export_controller
        try:
            export_controller({str(controllers[0])!r}, "c", {str(out)!r})
        except (OSError, ValueError) as exc:
            print("refused:", exc)
    """, limit)
    assert "refused:" in done.stdout, done.stdout + done.stderr
    assert _snapshot(out) == before and sorted(out.parent.iterdir()) == siblings
    export_controller(controllers[0], "c", out)                          # without the limit: replaced whole
    assert _snapshot(out)[DATA_HEADER] != before[DATA_HEADER] and {p.name for p in out.iterdir()} == set(OWNED)


def test_a_c_export_never_replaces_a_folder_holding_other_files(controllers, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(ValueError, match="holds files the export does not write \\(notes.txt\\)"):
        export_controller(controllers[0], "c", out)
    assert _snapshot(out) == {"notes.txt": b"keep me"}


def test_signing_and_saving_that_fail_part_way_leave_nothing_behind(controllers, tmp_path):
    priv, _ = keygen(tmp_path / "k")
    work = tmp_path / "w"
    work.mkdir()
    src = work / "robust.json"
    src.write_text(controllers[0].read_text())
    before = _snapshot(work)
    done = _run_limited(f"""
        from design.files.linear import read_controller_file
        from design.files.load import sign_file
        from design.files.signature import load_private_key
        for write in (lambda: sign_file({str(src)!r}, load_private_key({str(priv)!r})),
                      lambda: read_controller_file({str(src)!r}).save({str(work / "copy.json")!r})):
            try:
                write()
            except (OSError, ValueError) as exc:
                print("refused:", exc)
    """, src.stat().st_size // 2)
    assert done.stdout.count("refused:") == 2, done.stdout + done.stderr
    assert _snapshot(work) == before                                     # no .part, no temporary, src whole


def test_a_file_at_the_old_temporary_name_is_not_written_through(controllers, tmp_path):
    priv, _ = keygen(tmp_path / "k")
    victim = tmp_path / "victim.txt"
    victim.write_text("not yours")
    out = tmp_path / "signed.json"
    (tmp_path / "signed.json.part").symlink_to(victim)
    sign_file(controllers[0], load_private_key(priv), out)
    assert victim.read_text() == "not yours" and not out.is_symlink()
    assert load_controller(out).name == "linear:robust"
