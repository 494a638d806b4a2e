"""Diagnosis of a short-stroke output-angle torque (plant2 output_periodic): which stand-in, and where it is judged.

Rebuilds discover's tau_m baseline (its identified tanh width, standstill rows out) on a case's bags and scores, on
the fit blocks' CV and on the held-out bag (inside and beyond the fit rows' range of theta_f separately, with the
paired z against greedy's answer, the order-3 harmonic): the cubic stand-in with its powers as plain polynomials
(before the twenty-fifth pass), continued linearly beyond the fit range (hd_twin.terms.pow_within, the pass), clamped
(held at its bound), lower degrees, and harmonics of orders 1-4. Whether periodicity was identifiable: the stroke in
revolutions and in periods of each order, and the CV of every reading. Diagnosis only: nothing here feeds an estimator.

    python bench/diag_short_stroke.py CASE_DIR [REPORT_JSON]
"""

from __future__ import annotations

import glob
import json
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as B
    from diag_models import ModelTable
    from hd_ground.discovery.core import Options, chunked_paired_z, standstill_rows
    from hd_twin.terms import pow_within

    args = argv if argv is not None else sys.argv[1:]
    case = Path(args[0])
    rep = json.loads(Path(args[1] if len(args) > 1 else case / "discovery" / "report.json").read_text())
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    ds, ho = B.discover_dataset(bags)
    keep = ~standstill_rows(ds, Options().standstill_sigmas)[0]
    sig = {k: v[keep] for k, v in ds.signals.items()}
    hok, blk = ho[keep], ds.block[keep]
    fit = ~hok
    y, w, th = sig["tau_m"], sig["omega_m"], sig["theta_f"]
    s0 = next(x for x in rep["signals"] if x["signal"] == "tau_m")
    eps = s0["baseline_parameters"]["eps_omega"]
    avail = {k for k, v in sig.items() if np.std(v) > 0}
    base = [sig["alpha_m"]] + ([sig["alpha_m_dot"]] if "alpha_m_dot" in avail else []) + (
        [sig["Q_red_over_N"]] if "Q_red_over_N" in avail else []) + [w, np.tanh(w / eps)]
    lo, hi = float(th[fit].min()), float(th[fit].max())
    c = float(np.median(th[fit]))
    out = hok & ((th < lo) | (th > hi))
    print(f"fit range of theta_f [{lo:+.3f}, {hi:+.3f}] rad = {(hi - lo) / (2 * np.pi):.3f} revolutions "
          f"(order k: {(hi - lo) / (2 * np.pi):.3f} k periods); held-out range [{th[hok].min():+.3f}, "
          f"{th[hok].max():+.3f}]: {out.sum()} of {hok.sum()} held-out rows ({out.sum() / hok.sum():.1%}) beyond it")
    T = ModelTable(y, fit, hok, blk, width=40)
    u = th - c
    models = {"baseline": base}
    for d in (1, 2, 3):
        models[f"poly{d} (plain powers)"] = base + [u**k for k in range(d + 1)]
    models["poly3 continued linearly (the pass)"] = base + [np.ones_like(u)] + [pow_within(th, k, c, lo, hi)
                                                                                for k in (1.0, 2.0, 3.0)]
    models["poly3 clamped at the bounds"] = base + [(np.clip(th, lo, hi) - c) ** k for k in range(4)]
    for k in (1, 2, 3, 4):
        models[f"sin/cos {k} theta_f"] = base + [np.sin(k * th), np.cos(k * th)]
    ref = "sin/cos 3 theta_f"
    T.report(ref, models[ref])
    rG = T.rows[ref][0]
    io = out[hok]
    print(f"{'model':40s} {'CV (fit)':>9s} {'held-out':>9s} {'inside':>9s} {'beyond':>9s}  paired z vs [{ref}]")
    for name, cols in models.items():
        r, cv = T.score(cols)
        rms = lambda e: float(np.sqrt(np.mean(e**2))) if e.size else float("nan")  # noqa: E731
        print(f"{name:40s} {np.sqrt(cv.sum() / fit.sum()):9.5f} {rms(r):9.5f} {rms(r[~io]):9.5f} {rms(r[io]):9.5f}  "
              f"{chunked_paired_z(r**2 - rG**2, 20):+.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
