"""Plant simulator speed: simulated seconds per wall second per actuator (median), ratio to real time.

Baseline measured in the same run: the same kernel with the *baseline* effect
set (fewest terms), so the ratio shows the cost of the realistic effect set.
Usage: ``hdphm bench sim [--duration S] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench sim", description=__doc__)
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    from hd_sim import EffectSet, simulate_mission

    simulate_mission(None, None, "inspection", 0, duration=0.5)  # compile / load cache
    res = {}
    for label, eff in (("baseline effects", EffectSet.baseline()), ("default (all realistic) effects",
                                                                    EffectSet.default())):
        rates = []
        for r in range(a.repeats):
            t0 = time.perf_counter()
            simulate_mission(None, eff, "inspection", r, duration=a.duration)
            rates.append(a.duration / (time.perf_counter() - t0))
        res[label] = statistics.median(rates)
        print(f"{label:34s}: median {res[label]:7.1f} simulated s / wall s per actuator "
              f"(= {res[label]:.1f}x real time at 1 kHz output, dt = 25 us; target >= 20x)")
    b, d = res["baseline effects"], res["default (all realistic) effects"]
    print(f"ratio default / baseline speed: {d / b:.2f}")
    return 0 if d >= 20.0 else 1


if __name__ == "__main__":
    sys.exit(main())
