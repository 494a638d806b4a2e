"""Diagnosis of the smooth-cubic Stribeck case of ``hdphm bench discover`` (issue 10), with the simulator's truth.

Diagnosis only (it reads ``/sim/effects``; nothing here feeds an estimator). Reproduces the README's "Still missed"
figures: where the fit missions carry the friction curve, the held-out error of the true shape with least-squares
coefficients, the spread of the curve at the held-out speed among shapes of nearly equal CV error, the effect of
the acceleration's derivative window, and the greedy reference without its temperature group and selecting on the
fit bags' CV instead of the held-out bag.

    hdphm bench discover --extra --families smooth-cubic --family-effects stribeck_friction --no-plant2 --out runs/sc
    python bench/diag_discover_gap.py runs/sc/smooth-cubic/stribeck_friction/bags
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_discover import read_truth
    from hd_bag import read_mission
    from hd_ground.discovery import greedy as G
    from hd_ground.discovery.core import _lstsq, choose_speed_timing, standstill_rows
    from hd_ground.discovery.data import dataset_from_missions
    from hd_twin.identify import BlockGram

    d = (argv or sys.argv[1:])[0]
    bags = sorted(glob.glob(str(Path(d) / "*.mcap")))
    e = read_truth(bags[0])["effects"]
    tc, ratio, ws_t, de_t = e["coulomb_friction"]["T_C"], e["stribeck_friction"]["ratio"], e["stribeck_friction"]["omega_s"], \
        e["stribeck_friction"]["delta"]
    width, b_t = e["smooth_friction"]["width"], e["viscous_friction"]["b"]
    print(f"truth: T_C {tc}, T_S - T_C {(ratio - 1) * tc:.3g}, omega_s {ws_t}, delta {de_t}, width {width:.3g}, "
          f"temperature_dependent_friction on: {e['temperature_dependent_friction']['on']}")
    ms = [read_mission(b) for b in bags]
    for win in (0.02, 0.005):
        ds = dataset_from_missions(ms, bags, alpha_window_s=win)
        ho = ds.bag == len(bags) - 1
        if ds.speed_lags:
            ds = choose_speed_timing(dataset_from_missions(ms, bags, retime_speeds=False, alpha_window_s=win), ds, ho)[0]
        still = standstill_rows(ds, 3.0)[0]
        ds, ho = ds.subset(~still), ho[~still]
        fit = ~ho
        s, y, w = ds.signals, ds.signals["tau_m"], ds.signals["omega_m"]
        aw, aa = np.abs(w), np.abs(s["alpha_m"])
        print(f"\n== alpha_m derivative window {win * 1e3:g} ms")
        if win == 0.02:
            for b in range(len(bags)):
                m = ds.bag == b
                print(f"bag {b}{' (held out)' if b == len(bags) - 1 else ''}: temperature {np.median(s['temperature'][m]):.1f} "
                      f"degC, |omega_m| q10/50/90 {np.round(np.quantile(aw[m], [.1, .5, .9]), 2).tolist()} rad/s")
            for lo, hi in ((0, 1), (1, 3), (3, 8), (8, 11), (11, 14), (14, 30), (30, 1e9)):
                m = fit & (aw >= lo) & (aw < hi)
                print(f"  fit rows {lo:g}-{hi:g} rad/s: {m.sum()}, median |alpha_m| {np.median(aa[m]) if m.any() else 0:.0f} rad/s^2")

        def X(o, dl, ep):
            sg = np.tanh(w / ep)
            return np.stack([s["alpha_m"], s["Q_red_over_N"], w, sg, np.exp(-(aw / o) ** dl) * sg], 1)

        F = (tc + (ratio - 1) * tc * np.exp(-(aw / ws_t) ** de_t)) * np.tanh(w / width) + b_t * w
        M = np.stack([s["alpha_m"], s["Q_red_over_N"]], 1)
        r = y - F - M @ _lstsq(M[fit], (y - F)[fit])
        print(f"true friction fixed (J, eta fitted): fit RMSE {np.sqrt(np.mean(r[fit] ** 2)):.4f}, held-out "
              f"{np.sqrt(np.mean(r[ho] ** 2)):.4f} N*m (the floor)")
        Mt = X(ws_t, de_t, width)
        bt = _lstsq(Mt[fit], y[fit])
        rt = y - Mt @ bt
        print(f"true shape, least-squares coefficients: T_C {bt[3]:.4g}, T_S - T_C {bt[4]:.4g}; held-out "
              f"{np.sqrt(np.mean(rt[ho] ** 2)):.4f}")
        v0 = float(np.median(aw[ho]))
        rows = []
        for o in np.geomspace(2, 20, 13):
            for dl in np.geomspace(0.5, 5, 9):
                for ep in np.geomspace(0.3, 15, 12):
                    Mx = X(o, dl, ep)
                    g = BlockGram(Mx[fit], y[fit], ds.block[fit])
                    c = g.coef()
                    fv = c[2] * v0 + (c[3] + c[4] * np.exp(-(v0 / o) ** dl)) * np.tanh(v0 / ep)
                    rows.append((float(np.nansum(g.cv_sse())), o, dl, ep, fv, float(np.sqrt(np.mean((y - Mx @ c)[ho] ** 2)))))
        rows.sort()
        near = [x for x in rows if x[0] <= 1.01 ** 2 * rows[0][0]]
        f_true = b_t * v0 + (tc + (ratio - 1) * tc * np.exp(-(v0 / ws_t) ** de_t)) * np.tanh(v0 / width)
        print(f"shapes within 1 % of the best CV error (grid 13 x 9 x 12): {len(near)}; friction at the held-out "
              f"{v0:.3g} rad/s {min(x[4] for x in near):.3g}..{max(x[4] for x in near):.3g} N*m (truth {f_true:.3g}); "
              f"held-out {min(x[5] for x in near):.3g}..{max(x[5] for x in near):.3g}")
    # greedy (on the speeds discover uses), without the temperature group, and selecting on the fit bags' CV
    ds = dataset_from_missions(ms, bags)
    ho = ds.bag == len(bags) - 1
    if ds.speed_lags:
        ds = choose_speed_timing(dataset_from_missions(ms, bags, retime_speeds=False), ds, ho)[0]
    still = standstill_rows(ds, 3.0)[0]
    r = G.greedy_discover(ds, "tau_m", ho, standstill=still)
    print(f"\ngreedy (selected on the held-out bag): {r['error_after']['rmse']:.5f}, {[x['name'] for x in r['effects']]}")
    og = G._groups
    try:
        G._groups = lambda *a: [g for g in og(*a) if g[0] != "temperature_dependent_friction"]
        r = G.greedy_discover(ds, "tau_m", ho, standstill=still)
        print(f"greedy without the temperature group: {r['error_after']['rmse']:.5f}, {[x['name'] for x in r['effects']]}")
    finally:
        G._groups = og
    keep = ~still
    sig = {k: v[keep] for k, v in ds.signals.items()}
    h, blk = ho[keep], ds.block[keep]
    fit = ~h
    y, w = sig["tau_m"], sig["omega_m"]
    scale = float(np.quantile(np.abs(w[fit]), 0.9))
    best = None
    for eps in np.geomspace(1e-3, 0.3, 8) * scale:
        Xb = np.stack([sig["alpha_m"], np.tanh(w / eps), w, sig["Q_red_over_N"]], 1)
        rr = y[fit] - Xb[fit] @ G._lstsq(Xb[fit], y[fit])
        if best is None or rr @ rr < best[0]:
            best = (rr @ rr, eps, Xb)
    _, eps, Xc = best

    def cv(Xm):
        return float(np.nansum(BlockGram(Xm[fit], y[fit], blk[fit]).cv_sse()))
    groups = G._groups(sig, "tau_m", eps, {k for k, v in sig.items() if np.std(v) > 0})
    cur, used = cv(Xc), []
    while len(used) < 6:
        e_, i = min((cv(np.column_stack([Xc] + g[3])), i) for i, g in enumerate(groups) if i not in used)
        if (cur - e_) / cur < 0.02:
            break
        used.append(i)
        Xc, cur = np.column_stack([Xc] + groups[i][3]), e_
    b = G._lstsq(Xc[fit], y[fit])
    print(f"greedy selecting on the fit bags' leave-one-block-out CV: held-out {np.sqrt(np.mean((y - Xc @ b)[h] ** 2)):.5f}, "
          f"CV RMSE {np.sqrt(cur / fit.sum()):.5f}, {[groups[i][0] for i in used]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
