#!/usr/bin/env python3
"""Run every benchmark (``benchmarks/bench_*.py``) and print their tables.

    python3 tasks.py bench                 # all of them
    python3 tasks.py bench simulator gnss  # those whose name contains a word

Each benchmark compares against a peer or a baseline *in the same run* and
reports ratios, because these machines are shared and noisy.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    benches = sorted(HERE.glob("bench_*.py"))
    words = [a for a in argv if not a.startswith("-")]
    if words:
        benches = [b for b in benches if any(w in b.stem for w in words)]
        if not benches:
            print(f"no benchmark matches {words}; have {[b.stem for b in sorted(HERE.glob('bench_*.py'))]}",
                  file=sys.stderr)
            return 2
    status = 0
    for b in benches:
        print(f"\n=== {b.stem} ===", flush=True)
        done = subprocess.run([sys.executable, str(b), *[a for a in argv if a.startswith("-")]])
        status = status or done.returncode
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
