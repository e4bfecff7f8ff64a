"""Line capture of the integral (design.capture) in every integral controller of the toolkit.

After an engage the integral must stay at zero while the tractor approaches the line and
start once the measured cross-track first comes within the capture distance; a reset (the
loop's engage) re-arms it. ``math.inf`` restores integration from the engage on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.baselines import PurePursuitController, StanleyController
from design.capture import INTEGRAL_CAPTURE_M, LineCapture
from design.controller import Measurement
from design.controller_file import LinearController, integrator_rows
from design.errors import DesignInputError
from design.mpc import build_mpc
from design.robust import RobustSpec, design_robust

from design_family import family, tractor_model


def m(t: float, y: float, v: float = 1.79) -> Measurement:
    return Measurement(t, y, 0.0, 0.0, v)


def test_line_capture_latches_and_re_arms():
    c = LineCapture(0.05)
    assert not c.update(0.3) and not c.update(-0.051)
    assert c.update(-0.05) and c.update(0.4)           # latched: a later excursion does not release it
    c.reset()
    assert not c.update(0.2)
    assert LineCapture(math.inf).update(5.0)
    for bad in (0, -0.1, math.nan, True, "0.05"):
        with pytest.raises(DesignInputError, match="capture distance"):
            LineCapture(bad)


@pytest.fixture(scope="module")
def robust_files():
    models = family(speeds=(1.0, 2.0), authorities=(1.0, 0.6))
    return {integral: design_robust(models, RobustSpec(integral=integral)).file for integral in (True, False)}


def test_integrator_rows_are_found_only_in_an_integral_design(robust_files):
    with_int, without = robust_files[True], robust_files[False]
    rows = integrator_rows(with_int.compensator)
    assert rows.size == 1
    c = with_int.compensator
    assert c.Ac[rows[0], rows[0]] == 1.0 and c.Bc[rows[0], 0] == pytest.approx(c.dt)
    assert integrator_rows(without.compensator).size == 0


def test_linear_controller_integrates_only_after_capture(robust_files):
    spec = robust_files[True]
    ctrl = LinearController(spec)
    r = int(integrator_rows(spec.compensator)[0])
    ctrl.reset()
    for k in range(40):                                  # 2 s at 0.3 m: approaching, no integral
        ctrl.step(m(k * 0.05, 0.3))
        assert ctrl.estimate()[r] == 0.0
    ctrl.step(m(2.0, 0.04))                              # captured: the integral starts
    ctrl.step(m(2.05, 0.3))
    assert ctrl.estimate()[r] != 0.0
    ctrl.reset()
    ctrl.step(m(0.0, 0.3))
    assert ctrl.estimate()[r] == 0.0                     # re-armed by the engage
    free = LinearController(spec, integral_capture=math.inf)
    free.reset()
    free.step(m(0.0, 0.1))                               # (y/V within the file's output clip of 0.1 s)
    assert free.estimate()[r] == pytest.approx(0.05 * 0.1 / 1.79)       # dt * y/V from the first step


def test_mpc_integrates_only_after_capture():
    ctrl = build_mpc(tractor_model(1.79, name="central"), 10, time_budget=1.0)
    (slot,) = ctrl.integral_slots
    ctrl.reset()
    for k in range(20):
        ctrl.step(m(k * 0.05, -0.2))
        assert ctrl.estimate()[slot] == 0.0
    ctrl.step(m(1.0, -0.01))
    assert ctrl.estimate()[slot] == pytest.approx(0.05 * -0.01 / 1.79)
    ctrl.reset()
    ctrl.step(m(0.0, -0.2))
    assert ctrl.estimate()[slot] == 0.0


@pytest.mark.parametrize("cls", [PurePursuitController, StanleyController])
def test_baselines_integrate_only_after_capture(cls):
    ctrl = cls()
    ctrl.reset()
    for k in range(20):
        ctrl.step(m(k * 0.05, 0.5))
        assert ctrl.estimate()[0] == 0.0
    ctrl.step(m(1.0, INTEGRAL_CAPTURE_M))
    assert ctrl.estimate()[0] == pytest.approx(0.05 * INTEGRAL_CAPTURE_M)
    ctrl.reset()
    assert ctrl.estimate()[0] == 0.0
