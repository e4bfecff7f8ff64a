#!/usr/bin/env python3
"""HIL bench speed and real-time behaviour (issue 5's benchmark).

1. Lockstep speed, virtual seconds per wall second ("x real time"), of
   (a) the truth simulator alone (one tractor, the baseline),
   (b) the bridge path alone (firmware + host driver, every frame encoded, line-timed, decoded),
   (c) the full closed loop: bridge and receivers encoded and decoded every cycle, GNSS
       front-end, guidance, controller, engagement logic, recording.
   Target for (c): 500x real time on one core.
2. Real time over pseudo-terminals at 20 Hz: deadline misses, loop time median/p99/max,
   lateness of the cycle start, and command-to-valve latency (9600 baud line time included).
   Target: loop time p99 < 5 ms and no missed deadline on an idle machine.
"""

from __future__ import annotations

import argparse
import time

from design.controller import KinematicLQRController
from hil.bridge.measure import measure_lockstep_speed, measure_pty_latency
from hil.conditions import condition_for
from hil.plant import SimulatedTractor
from hil.run import RunSpec, simulated_run, summarize


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0, help="virtual seconds per lockstep case")
    ap.add_argument("--realtime", type=float, default=20.0, help="seconds of the real-time pty run")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    dur, rt = (15.0, 5.0) if a.quick else (a.duration, a.realtime)
    cond = condition_for("disker", 1.79)

    plant = SimulatedTractor(cond, dur + 1, 1)
    w0 = time.perf_counter()
    for _ in range(int(round(dur / plant.params.dt))):
        plant.advance(plant.params.dt)
    sim_only = dur / (time.perf_counter() - w0)

    bridge = measure_lockstep_speed(SimulatedTractor(cond, dur + 1, 1), duration=dur).speedup

    ctrl = KinematicLQRController()
    w0 = time.perf_counter()
    log = simulated_run(RunSpec(implement="disker", speed=1.79, duration=dur, seed=1), ctrl)
    full = dur / (time.perf_counter() - w0)
    s = summarize(log)

    print(f"{'lockstep case':<48}{'x real time':>12}{'vs simulator':>14}")
    for name, v in (("(a) simulator alone, 1 tractor (baseline)", sim_only),
                    ("(b) bridge firmware + driver + simulator", bridge),
                    ("(c) full loop, bridge + receivers + front-end", full)):
        print(f"{name:<48}{v:>12.0f}{v / sim_only:>14.2f}")
    print(f"target (c) >= 500x: {'met' if full >= 500 else 'NOT met'}; loop time in lockstep p50 "
          f"{s['loop_time_ms_p50']:.2f} ms, p99 {s['loop_time_ms_p99']:.2f} ms")

    rlog = simulated_run(RunSpec(implement="disker", speed=1.79, duration=rt, seed=1, realtime=True), ctrl)
    r = summarize(rlog)
    lat = measure_pty_latency(SimulatedTractor(cond, 30, 2), samples=40)
    print(f"\nreal time over pseudo-terminals, {rt:.0f} s at 20 Hz")
    print(f"{'cycles':<34}{r['cycles']:>10}")
    print(f"{'deadline misses':<34}{r['deadline_misses']:>10}")
    print(f"{'loop time median / p99 / max, ms':<34}{r['loop_time_ms_p50']:>10.2f}{r['loop_time_ms_p99']:>10.2f}"
          f"{r['loop_time_ms_max']:>10.2f}")
    print(f"{'cycle start lateness p99, ms':<34}{r['lateness_ms_p99']:>10.2f}")
    print(f"{'command-to-valve median / max, ms':<34}{lat.command_to_valve_median * 1e3:>10.2f}"
          f"{lat.command_to_valve_max * 1e3:>10.2f}   (line time {lat.wire_command * 1e3:.3f} ms)")
    print(f"{'ping round trip median / p99, ms':<34}{lat.ping_rtt_median * 1e3:>10.2f}{lat.ping_rtt_p99 * 1e3:>10.2f}")
    print(f"target loop p99 < 5 ms and no miss: "
          f"{'met' if r['loop_time_ms_p99'] < 5 and r['deadline_misses'] == 0 else 'NOT met'}")


if __name__ == "__main__":
    main()
