"""Diagnosis of a Q_red case where ``hdphm bench discover``'s greedy reference scores lower on the held-out bag.

The Q_red twin of ``diag_tau_m_vs_greedy.py``: rebuilds discover's final Q_red model (its baseline K w + c w' +
alpha_f and its terms, read from the report's bases) and greedy's (replayed step by step with the same code path as
``greedy.greedy_discover``), on the same rows and the same twist (theta_f smoothed over discover's window, or the
``--twist`` windows given), and scores each model, and swaps between them, two ways: the held-out bag's RMSE (what
the bench judges) and the leave-one-block-out CV error of the fit blocks (what discover may choose on). A group that
lowers the held-out error but not the fit blocks' CV is the held-out bag's own; one that lowers both is one the fit
data support and discover missed. Diagnosis only: nothing here feeds an estimator.

    python bench/diag_qred_vs_greedy.py CASE_DIR [REPORT_JSON] [--twist 0,9,17] [--j J1,J2,...]

``--j``: dead-zone widths at which to compare the KE variants (e.g. discover's width while it selected, from an
instrumented run, against its final one).
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
    from hd_ground.discovery.data import with_smoothed_twist
    from hd_ground.discovery.greedy import _groups
    from hd_twin.terms import basis_matrix

    args = list(argv if argv is not None else sys.argv[1:])
    windows = None
    jscan = []
    if "--j" in args:
        i = args.index("--j")
        jscan = [float(x) for x in args[i + 1].split(",")]
        del args[i:i + 2]
    if "--twist" in args:
        i = args.index("--twist")
        windows = [int(x) for x in args[i + 1].split(",")]
        del args[i:i + 2]
    case = Path(args[0])
    rep = json.loads(Path(args[1] if len(args) > 1 else case / "discovery" / "report.json").read_text())
    s0 = next(x for x in rep["signals"] if x["signal"] == "Q_red")
    tw_d = int(rep.get("twist_window_samples", 0))
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    ds0, ho = B.discover_dataset(bags)
    fit = ~ho
    blk = ds0.block
    print(f"rows: fit {fit.sum()} in {len(np.unique(blk[fit]))} blocks, held-out {ho.sum()}; discover's twist "
          f"window {tw_d}")
    for t in s0["terms"]:
        par = {k: round(v, 6) for k, v in t["parameters"].items() if not k.endswith(("_sd", "_se", "_weak"))}
        print(f"discover term: {t['name']}({t['variable']}, {t.get('order')}) {json.dumps(par)}")

    for tw in (windows or [tw_d]):
        ds = with_smoothed_twist(ds0, tw) if tw else ds0
        sig = ds.signals
        y = sig["Q_red"]
        avail = {k for k, v in sig.items() if np.std(v) > 0}
        print(f"\n===== twist window {tw} =====")
        table = ModelTable(y, fit, ho, blk, width=52, digits=4)
        score, report = table.score, table.report

        base = [sig["windup"], sig["windup_dot"]] + ([sig["alpha_f"]] if "alpha_f" in avail else [])
        tc = {f"{t['name']}:{t.get('order')}:{t['form'].split()[1 if t['form'].startswith('K ') else 0]}":
              [basis_matrix(t["basis"], sig)[:, j] for j in range(len(t["basis"]))] for t in s0["terms"]}
        B0 = "baseline K w + c w' + alpha_f"
        report(B0, base)
        D = "discover final (" + ", ".join(tc) + ")"
        dcols = base + [c for v in tc.values() for c in v]
        report(D, dcols, B0)
        # greedy replay (greedy.greedy_discover's loop)
        eps = float(np.quantile(np.abs(sig["omega_m"][fit]), 0.9)) * 1e-2
        groups = _groups(sig, "Q_red", eps, avail)
        names = []
        for i, g in enumerate(groups):
            n = f"{g[0]}({g[1]}, {g[2]})"
            if g[0] == "backlash":
                sc = float(np.quantile(np.abs(sig["windup"]), 0.9))
                n += f" j={np.geomspace(0.02, 0.3, 4)[sum(1 for h in groups[:i] if h[0] == 'backlash')] * sc:.3g}"
            names.append(n)
        cols, chosen, G = table.greedy_replay(base, B0, groups, names)
        report("(greedy final vs discover final)", cols, D)
        print("-- each greedy group added to discover's final model:")
        for i in chosen:
            report(f"discover + {names[i]}", dcols + groups[i][3], D)
        print("-- every greedy group on discover's final model, top 8 by the fit blocks' CV:")
        res = sorted((score(dcols + g[3])[1].sum(), i) for i, g in enumerate(groups))
        for _, i in res[:8]:
            report(f"  D + {names[i]}", dcols + groups[i][3], D)
        print("-- variants of discover's model (its dead zone kept):")
        bl = next((v for k, v in tc.items() if k.startswith("backlash:")), [])
        s2 = lambda k: [np.sin(k * sig["theta_m"]), np.cos(k * sig["theta_m"])]
        wu = sig["windup"]
        aw = np.abs(wu)
        kel = lambda k: [c * aw for c in s2(k)]
        pds = lambda k: [c * wu for c in s2(k)]
        V = {
            "dz + KE2 plain": bl + s2(2),
            "dz + KE2 load": bl + kel(2),
            "dz + KE2 plain + KE2 load": bl + s2(2) + kel(2),
            "dz + KE2 plain + PDS2": bl + s2(2) + pds(2),
            "dz + KE2 load + PDS2 (= discover)": bl + kel(2) + pds(2),
            "dz + KE2 plain + KE2 load + PDS2": bl + s2(2) + kel(2) + pds(2),
            "dz + KE2 plain + KE4 plain": bl + s2(2) + s2(4),
            "dz + KE2 plain + KE4 plain + PDS1": bl + s2(2) + s2(4) + pds(1),
            "dz + KE2 load + PDS2 + KE4 plain": bl + kel(2) + pds(2) + s2(4),
            "dz + KE2 load + PDS2 + PDS1": bl + kel(2) + pds(2) + pds(1),
            "no dz: KE2 plain + KE4 plain + PDS1 (greedy's)": s2(2) + s2(4) + pds(1),
        }
        for k, v in V.items():
            report(k, base + v, D)
        if jscan:
            print("-- the dead zone's width (dz, dz^3 at width j) and the KE variant on it:")
        for j in jscan:
            dz = np.sign(wu) * np.maximum(np.abs(wu) - j, 0.0)
            bj = [dz, dz**3]
            for k, v in {"dz": bj, "dz + KE2 plain": bj + s2(2), "dz + KE2 load": bj + kel(2),
                         "dz + KE2 load + PDS2": bj + kel(2) + pds(2), "dz + KE2 plain + KE2 load": bj + s2(2) + kel(2),
                         "dz + KE2 load + KE2 plain + PDS2": bj + kel(2) + s2(2) + pds(2)}.items():
                report(f"j={j:.3g}: {k}", base + v, D)
        table.per_block(D, G, lambda b: int(ds.bag[blk == b][0]), fmt="12.1f")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
