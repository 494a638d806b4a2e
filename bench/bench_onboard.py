"""Onboard core throughput and latency (``hdphm bench onboard``).

Throughput: samples/s through conditioning + expected response + residuals +
detector, in blocks of 1000 (target >= 10 kHz on one core), for the
physics-only stand-in and, when ``--model-dir`` is given, the ONNX twin.
Latency: a 1 kHz stream fed one sample per call (as the node does at real
time), p50/p99 per-sample processing time (target p99 < 2 ms). Baseline in
the same run: a plain numpy pass over the same samples (residual of a fixed
linear model) to show the overhead ratio.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench onboard")
    ap.add_argument("--seconds", type=float, default=20.0, help="mission length [s] at 1 kHz")
    ap.add_argument("--model-dir", default="", help="trained twin (ONNX) to time as well")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "onboard"))
    from synth import make_mission

    from hd_onboard.core import OnboardCore, run_mission
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    m = make_mission(duration=a.seconds, seed=0, fault_at=a.seconds * 0.7)
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    kinds = [("standin", "")] + ([("onnx", a.model_dir)] if a.model_dir else [])
    t_base = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        r = V[:, 5] - 101.0 * V[:, 4]
        float(np.abs(r).max())
        t_base.append(time.perf_counter() - t0)
    base = m.n / np.median(t_base)
    print(f"baseline numpy residual pass: {base / 1e3:.0f} kS/s")
    for kind, md in kinds:
        p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
        ts = []
        for _ in range(a.repeat):
            core = OnboardCore(make_expected(md or None, p, fs_hz=1000.0), p)
            t0 = time.perf_counter()
            run_mission(m, core, block=1000)
            ts.append(time.perf_counter() - t0)
        thr = m.n / np.median(ts)
        core = OnboardCore(make_expected(md or None, p, fs_hz=1000.0), p)
        lat = np.empty(min(m.n, 10000))
        for i in range(len(lat)):
            t0 = time.perf_counter()
            core.push(stamps[i:i + 1], V[i:i + 1])
            lat[i] = time.perf_counter() - t0
        print(f"{kind}: throughput median {thr / 1e3:.1f} kS/s (target >= 10 kS/s: {'PASS' if thr >= 1e4 else 'FAIL'}); "
              f"ratio to baseline {base / thr:.0f}x slower; per-sample latency p50 {np.median(lat) * 1e3:.3f} ms, "
              f"p99 {np.percentile(lat, 99) * 1e3:.3f} ms (target < 2 ms: {'PASS' if np.percentile(lat, 99) < 2e-3 else 'FAIL'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
