"""Diagnosis: would a dead zone with a soft edge explain a Q_red case better than discover's hard one?

Rebuilds discover's final Q_red model from its report (the baseline K w + c w' + alpha_f and its terms' bases, on
discover's twist), then swaps its hard lost motion K_j dz(w; j) + k3_j dz(w; j)^3 for the same law of a dead zone
whose edges are softplus corners of width s (``hd_twin.terms``' ``deadzone`` op with ``edge``; hd_sim's form),
searching j around discover's width and s / j on a grid by the fit blocks' leave-one-block-out CV error (the choice
never sees the held-out bag), and scores the best both ways: the fit blocks' CV (what discover may choose on; its
admission rule asks for a 2 % CV gain in a majority of the blocks) and the held-out bag's RMSE. Diagnosis only:
nothing here feeds an estimator.

    python bench/diag_dead_zone_edge.py CASE_DIR [REPORT_JSON]
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
    from hd_ground.discovery.core import StateSignals
    from hd_ground.discovery.data import with_smoothed_twist
    from hd_twin.terms import basis_matrix

    args = list(argv if argv is not None else sys.argv[1:])
    if not args:
        print(__doc__)
        return 2
    case = Path(args[0])
    rep = json.loads(Path(args[1] if len(args) > 1 else case / "discovery" / "report.json").read_text())
    s0 = next(x for x in rep["signals"] if x["signal"] == "Q_red")
    gap = next((t for t in s0["terms"] if t["name"] == "backlash"), None)
    if gap is None:
        print(f"{case}: discover's Q_red model has no lost motion; nothing to compare")
        return 1
    tw = int(rep.get("twist_window_samples", 0))
    ds0, ho = B.discover_dataset(sorted(glob.glob(str(case / "bags" / "*.mcap"))))
    ds = with_smoothed_twist(ds0, tw) if tw else ds0
    sig = StateSignals(ds.signals, (ds.signals, ds.segment, {}), np.arange(ds.n))
    avail = {k for k, v in ds.signals.items() if np.std(v) > 0}
    y, fit = sig["Q_red"], ~ho
    table = ModelTable(y, fit, ho, ds.block, width=52, digits=4)
    base = [sig["windup"], sig["windup_dot"]] + ([sig["alpha_f"]] if "alpha_f" in avail else [])
    others = [basis_matrix(t["basis"], sig)[:, k] for t in s0["terms"] if t["name"] != "backlash"
              for k in range(len(t["basis"]))]
    j_d = float(gap["parameters"]["j"])

    def soft(j, s):  # hd_twin.terms' dead zone with softplus corners of width s
        return basis_matrix([{"op": "deadzone", "var": "windup", "width": float(j), "edge": float(s)}], sig)[:, 0]

    hard = basis_matrix([{"op": "deadzone", "var": "windup", "width": j_d}], sig)[:, 0]
    name = f"discover final (hard dz, j = {j_d:.3g})"
    table.report(name, base + [hard, hard**3] + others)
    best = None
    for j in j_d * np.array([0.6, 0.8, 0.9, 1.0, 1.1, 1.25, 1.5]):
        for r in (0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.8):
            d = soft(j, r * j)
            cv = float(table.score(base + [d, d**3] + others)[1].sum())
            if best is None or cv < best[0]:
                best = (cv, float(j), r)
    _, j, r = best
    d = soft(j, r * j)
    table.report(f"soft edge: j = {j:.3g}, s / j = {r}", base + [d, d**3] + others, name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
