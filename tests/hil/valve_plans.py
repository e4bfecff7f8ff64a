"""Test helper: the valve test's plan before its duties were cut to ten, for the tests whose scenario (a pass, a
refused model) was found on the curve it measured: another curve, within the test's noise of it, drives other
passes."""

from __future__ import annotations

from hil.vehicle.valve_steps import ValveTestPlan

#: Sixteen duties each way, the wheel brought to each step's start at 0.6 duty in at most 6 s.
SIXTEEN_DUTIES = ValveTestPlan(duties=(0.03, 0.06, 0.09, 0.12, 0.15, 0.18, 0.22, 0.26, 0.3, 0.35, 0.4, 0.5, 0.6, 0.7,
                                       0.85, 1.0), position_duty=0.6, position_time=6.0)
