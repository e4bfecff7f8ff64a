"""The valve test on the tractor's own bridge (``hil valve-test``, hil.vehicle.valve_run): the bridges it refuses.

Its run through the emulated tractor's HC11 pseudo-terminal in real time, writing the commissioning file, is
tested in ``test_field_procedure_end_to_end``, where the same valve test is the field procedure's first step
(made once there for both)."""

from __future__ import annotations

from hil.cli import main as hil_main


def test_an_agopengps_module_is_refused_with_the_reason_and_nothing_is_created(tmp_path, capsys):
    out = tmp_path / "vt"
    assert hil_main(["valve-test", "--bridge", "agopengps:udp:127.0.0.1:8888", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "closes its own loop on the wheel angle" in err[0]
    assert not out.exists()
    assert hil_main(["valve-test", "--bridge", "/dev/ttyS0", "--full-scale", "9", "--out", str(out)]) == 1
    assert "full_scale must be the bridge's rate at full duty" in capsys.readouterr().err and not out.exists()
