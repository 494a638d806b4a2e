"""Diagnosis of a tau_m case where ``hdphm bench discover``'s greedy reference scores lower on the held-out bag.

Rebuilds both final models on the same rows (the signals discover reads: its speed timing and acceleration choice,
standstill rows out) and scores each, and swaps between them, two ways: the held-out bag's RMSE (what the bench
judges) and the leave-one-block-out CV error of the fit blocks (what discover may choose on). A group that lowers
the held-out error but not the fit blocks' CV error is the held-out bag's own; a group or shape that lowers both
is one the fit data support and discover missed. Diagnosis only: nothing here feeds an estimator.

    python bench/diag_tau_m_vs_greedy.py CASE_DIR [REPORT_JSON]

CASE_DIR holds ``bags/*.mcap`` (the last bag held out, as the bench); REPORT_JSON is discover's report on them
(default CASE_DIR/discovery/report.json).
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
    from hd_ground.discovery.core import Options, StateSignals, _lstsq, chunked_paired_z, standstill_rows
    from hd_ground.discovery.greedy import _groups
    from hd_ground.discovery.prefilter import shifted_state_var
    from hd_twin.identify import presliding_state
    from hd_twin.terms import basis_matrix

    args = argv if argv is not None else sys.argv[1:]
    case = Path(args[0])
    rep = json.loads(Path(args[1] if len(args) > 1 else case / "discovery" / "report.json").read_text())
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    ds, ho = B.discover_dataset(bags)
    still = standstill_rows(ds, Options().standstill_sigmas)[0]
    keep = ~still
    sig = {k: v[keep] for k, v in ds.signals.items()}
    # discover's terms may read a pre-sliding state column (computed on the full time series, then cut)
    ssig = StateSignals(ds.signals, (ds.signals, ds.segment, {}), np.arange(ds.n)).rows_of(keep)
    hok, blk = ho[keep], ds.block[keep]
    fit = ~hok
    y, w = sig["tau_m"], sig["omega_m"]
    avail = {k for k, v in sig.items() if np.std(v) > 0}
    nfb = len(np.unique(blk[fit]))
    print(f"rows: fit {fit.sum()} in {nfb} blocks, held-out {hok.sum()}; acceleration window "
          f"{getattr(ds, 'alpha_window', '?')}")
    table = ModelTable(y, fit, hok, blk, width=58, digits=5)
    rows, score, report = table.rows, table.score, table.report

    s0 = rep["signals"][0] if rep["signals"][0]["signal"] == "tau_m" else next(
        x for x in rep["signals"] if x["signal"] == "tau_m")
    bp = s0["baseline_parameters"]
    # discover: baseline inertia/timing/load path/viscous + its friction direction + its terms
    dbase = [sig["alpha_m"]] + ([sig["alpha_m_dot"]] if "alpha_m_dot" in avail else []) + (
        [sig["Q_red_over_N"]] if "Q_red_over_N" in avail else []) + [w]
    eps_d = float(bp.get("eps_omega", 0.0))
    if "presliding_distance" in bp:  # discover's baseline friction direction is a pre-sliding state
        d_ps, sh_ps = bp["presliding_distance"], bp.get("presliding_timing_samples", 0.0)
        fdir = ssig[shifted_state_var("theta_m", d_ps, sh_ps)]
        print(f"discover baseline: pre-sliding state d {d_ps:.4g} rad, timing {sh_ps:+.2f} samples")
    else:
        fdir = np.tanh(w / eps_d) if eps_d > 0 else np.sign(w)
        print(f"discover baseline: tanh, eps {eps_d:.4g} rad/s")
    for t in s0["terms"]:
        par = {k: round(v, 4) for k, v in t["parameters"].items() if not k.endswith(("_sd", "_se", "_weak"))}
        print(f"discover term: {t['name']}({t['variable']}) {json.dumps(par)}")
    replaces_tc = any(t["name"] == "stribeck_friction" for t in s0["terms"])
    tcols = [basis_matrix(t["basis"], ssig)[:, j] for t in s0["terms"] for j in range(len(t["basis"]))]
    B0 = "discover baseline"
    report(B0, dbase + [fdir])
    D = "discover final"
    report(D, dbase + ([] if replaces_tc else [fdir]) + tcols, B0)

    # greedy, replayed with its trace (the same code path as greedy.greedy_discover)
    scale = float(np.quantile(np.abs(w[fit]), 0.9))
    best = None
    for eps in np.geomspace(1e-3, 0.3, 8) * scale:
        X = np.column_stack(dbase + [np.tanh(w / eps)])
        r = y[fit] - X[fit] @ _lstsq(X[fit], y[fit])
        if best is None or r @ r < best[0]:
            best = (float(r @ r), eps)
    eps_g = best[1]
    gbase = dbase + [np.tanh(w / eps_g)]
    t_ref = float(np.median(sig["temperature"][fit])) if "temperature" in avail else None  # greedy_discover's
    groups = _groups(sig, "tau_m", eps_g, avail, t_ref)
    G0 = f"greedy baseline (tanh eps_g {eps_g:.3g})"
    report(G0, gbase, D)
    names = [f"{g[0]}({g[1]}, {g[2]})" + (f" ws#{i}" if g[0] == "stribeck_friction" else "")
             for i, g in enumerate(groups)]
    _, chosen, G = table.greedy_replay(gbase, G0, groups, names)

    # swaps: each greedy group on top of discover's model, and discover's terms on greedy's baseline
    print("-- greedy's groups added to discover's model, one at a time:")
    dcols = dbase + ([] if replaces_tc else [fdir]) + tcols
    groups_d = _groups(sig, "tau_m", eps_d, avail, t_ref) if eps_d > 0 else groups  # on discover's friction direction
    # a second column of the current times a temperature offset (another reference) beside discover's own spans the
    # target itself (i_q = tau_m / k_t): never a comparison
    has_drift = any(t["name"] == "motor_thermal_drift" for t in s0["terms"])
    skip = {i for i, g in enumerate(groups) if has_drift and g[0] == "motor_thermal_drift"}
    for i in chosen:
        g = groups[i]
        if i in skip:
            print(f"   {g[0]}({g[1]}, {g[2]}) #{i}: in discover's model already (skipped)")
            continue
        report(f"discover + {g[0]}({g[1]}, {g[2]}) #{i}", dcols + g[3], D)
        if groups_d is not groups and g[3] is not groups_d[i][3]:
            report(f"discover + {g[0]}({g[1]}, {g[2]}) #{i} at eps_d", dcols + groups_d[i][3], D)
    print("-- every greedy group on discover's model (CV of the fit blocks; the top few by CV):")
    res = []
    for i, g in enumerate(groups):
        if i in skip:
            continue
        r, cv = score(dcols + g[3])
        res.append((cv.sum(), np.sqrt(np.mean(r**2)), i))
    for cvs, hr, i in sorted(res)[:6]:
        g = groups[i]
        print(f"   {g[0]}({g[1]}, {g[2]}) #{i}: CV SSE {(cvs - rows[D][1].sum()) / rows[D][1].sum() * 100:+.2f}%, "
              f"held-out {hr:.5f}")
    report("greedy baseline + discover's terms", gbase + tcols, G)
    # the friction direction as a pre-sliding state (rate-independent transition) on discover's model
    print("-- discover's model with a pre-sliding state s(theta_m; d) as the friction direction:")
    for t in s0["terms"]:
        bb = {b["op"]: b for b in t["basis"]}
        if t["name"] != "stribeck_friction" or "stribeck" not in bb:
            continue  # only a Stribeck term on tanh is moved onto the state here
        vs, de = bb["stribeck"]["v_s"], bb["stribeck"]["delta"]
        for d in np.geomspace(2e-4, 2e-2, 7):
            z = presliding_state(ds.signals["theta_m"], d, ds.segment)[keep]
            report(f"  d {d:.2e}: s, exp(-(|w|/{vs:.3g})^{de:.3g}) s",
                   dbase + [z, np.exp(-(np.abs(w) / vs) ** de) * z], D)
    # per-block CV of both final models
    table.per_block(D, G, lambda b: int(ds.bag[keep][blk == b][0]))
    rD, rG = rows[D][0], rows[G][0]
    print(f"held-out discover {np.sqrt(np.mean(rD**2)):.5f} greedy {np.sqrt(np.mean(rG**2)):.5f} paired z "
          f"{chunked_paired_z(rD**2 - rG**2, 20):+.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
