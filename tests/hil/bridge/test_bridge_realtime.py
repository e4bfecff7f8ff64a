"""The same host code over a pseudo-terminal in real time and over an in-memory link in lockstep.

Plant: the first-order TEST DOUBLE (tests/hil/bridge/bridge_plant_double.py).
"""

from __future__ import annotations

import statistics
import time
from itertools import groupby

import pytest
from bridge_plant_double import FirstOrderPlantDouble

from hil.bench.benches.bridge import LockstepBridge, PtyBridge
from hil.vehicle.bridge.driver import BridgeReport
from hil.vehicle.bridge.protocol import Ping, SteerRateCommand, frame_length

BT = 10 / 9600
STALL = 0.15   # s: a shared host stalls a thread this long now and then; real-time bounds allow for it
State = tuple[bool, bool, bool]


def scenario(bench: LockstepBridge | PtyBridge) -> list[BridgeReport]:
    """Engage, steer, fall silent (watchdog), re-engage, steer, disengage: 1.6 s of host code."""
    clock, drv = bench.clock, bench.driver
    reports: list[BridgeReport] = []
    t = clock.now()

    def cycle(until: float, rate: float | None) -> None:
        nonlocal t
        while t < until - 1e-9:
            t += 0.05
            clock.sleep_until(t)
            reports.extend(drv.poll())
            if rate is not None:
                drv.send_rate(rate)

    t0 = t
    cycle(t0 + 0.15, None)
    drv.engage()
    cycle(t0 + 0.55, 0.2)
    cycle(t0 + 1.0, None)  # silence: the watchdog trips 250 ms after the last command
    drv.engage()
    cycle(t0 + 1.35, -0.1)
    drv.disengage()
    cycle(t0 + 1.6, None)
    return reports


def states(reports: list[BridgeReport]) -> list[tuple[State, int]]:
    """Distinct consecutive (engaged, watchdog, override) states and how many reports showed each."""
    keyed = [(r.engaged, r.watchdog_tripped, r.manual_override) for r in reports]
    return [(k, len(list(g))) for k, g in groupby(keyed)]


EXPECTED = [(False, False, False), (True, False, False), (False, True, False), (True, False, False),
            (False, False, False)]


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_pty_in_real_time_and_memory_in_lockstep_report_the_same_sequence_of_states():
    plant_mem = FirstOrderPlantDouble()
    mem = LockstepBridge(plant_mem)
    plant_mem.now = mem.clock.now
    mem_reports = scenario(mem)

    plant_pty = FirstOrderPlantDouble()
    with PtyBridge(plant_pty) as pty:
        plant_pty.now = pty.clock.now
        wall0 = time.monotonic()
        pty_reports = scenario(pty)
        wall = time.monotonic() - wall0
    assert wall < 1.6 + 5.0, "1.6 s of host code took far longer than real time"

    s_mem, s_pty = states(mem_reports), states(pty_reports)
    # The order of states is exact in both; the counts are not in real time: jitter moves a state
    # boundary by a report either way, and a stalled device thread skips report slots (20 Hz:
    # 3 slots in a 150 ms stall), which shortens the state it falls in.
    assert [k for k, _ in s_mem] == EXPECTED
    assert [k for k, _ in s_pty] == EXPECTED
    slack = 2 + round(STALL * 20)
    for (_, n_mem), (_, n_pty) in zip(s_mem, s_pty):
        assert n_mem - slack <= n_pty <= n_mem + 2, (s_mem, s_pty)
    assert len(mem_reports) - 2 * slack <= len(pty_reports) <= len(mem_reports) + 2
    # The wheel moved the same way: left while engaged first, then right.
    for reports in (mem_reports, pty_reports):
        counts = [r.adc_counts for r in reports]
        assert max(counts) > 128 + 10 and counts[-1] < max(counts)
    for bench in (mem, pty):
        s = bench.driver.stats()
        assert s.bad_frames == 0 and s.timeouts == 0
    assert mem.driver.stats().report_gaps == 0      # in lockstep no slot is ever skipped


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_on_a_pty_a_command_still_takes_its_transmission_time_and_pings_measure_the_line():
    plant = FirstOrderPlantDouble()
    with PtyBridge(plant) as bench:
        plant.now = bench.clock.now
        drv, clock = bench.driver, bench.clock
        drv.engage()
        clock.sleep_until(clock.now() + 0.1)
        t_send = clock.now()
        drv.send_rate(0.35)
        clock.sleep_until(t_send + 0.1)
        rtts = [drv.ping(timeout=0.2) for _ in range(15)]
    t_effect = next(t for t, d in plant.duty_log if d != 0.0)
    wire = frame_length(SteerRateCommand(0.0)) * BT
    assert t_effect >= t_send + wire, "a pty ignores the baud rate; the emulator must not"
    assert t_effect <= t_send + wire + 0.01 + STALL
    two_frames = 2 * frame_length(Ping(0)) * BT
    assert min(rtts) >= two_frames
    # a ping may queue behind a report (18 bytes) in either direction; beyond that, a few ms of scheduling
    assert statistics.median(rtts) <= two_frames + 18 * BT + 0.005 + STALL / 3   # most pings see no stall
    assert bench.runner.late_max < 2 * STALL


@pytest.mark.timeout(20)
def test_lockstep_runs_are_bit_for_bit_reproducible():
    runs = []
    for _ in range(2):
        plant = FirstOrderPlantDouble()
        bench = LockstepBridge(plant)
        plant.now = bench.clock.now
        reports = scenario(bench)
        runs.append(([(r.received_at, r.seq, r.report) for r in reports], plant.duty_log, plant.angle))
    assert runs[0] == runs[1]
