#!/usr/bin/env python3
"""Simulator throughput: the batched sysid run against the same passes one at a time.

Prints CPU seconds for the paper's 15 conditions x N passes, the speed-up of
batching over the one-pass-at-a-time baseline (same seeds, identical logs), and
the real-time factor (simulated seconds per CPU second).
"""

from __future__ import annotations

import argparse
import time

from hil.bench.runs.sysid import SysidPlan, make_passes


def cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--quick", action="store_true", help="fewer, shorter passes")
    a = ap.parse_args()
    passes, duration = (1, 30.0) if a.quick else (a.passes, a.duration)
    plan = SysidPlan(passes=passes, duration=duration, seed=1)
    t_batch, batch = cpu(lambda: make_passes(plan))
    n = len(batch)
    t_single = 0.0
    same = True
    by_name = dict(batch)
    for cond in plan.conditions():
        one = SysidPlan(speeds=(cond.speed,), implements=(cond.implement,), passes=passes, duration=duration, seed=1)
        dt, logs = cpu(lambda: make_passes(one))
        t_single += dt
        same &= all(by_name[k].content_hash() == v.content_hash() for k, v in logs)
    sim_s = n * duration
    print(f"{'run':<28}{'passes':>8}{'CPU s':>10}{'CPU s/pass':>12}{'x real time':>13}")
    print(f"{'batched (hil sysid)':<28}{n:>8}{t_batch:>10.2f}{t_batch / n:>12.3f}{sim_s / t_batch:>13.0f}")
    print(f"{'one condition at a time':<28}{n:>8}{t_single:>10.2f}{t_single / n:>12.3f}{sim_s / t_single:>13.0f}")
    print(f"\nbatching speed-up: {t_single / t_batch:.1f}x; identical logs: {same}; "
          f"target: 15 x {passes} passes of {duration:.0f} s in well under 60 CPU s -> {t_batch:.1f} s")


if __name__ == "__main__":
    main()
