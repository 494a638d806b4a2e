"""Diagnosis of the smooth-cubic tau_m rows above greedy (issue 10, twenty-third pass): the friction transition's
shape profiled on the raw torque balance and on the balance filtered as the acceleration is (``prefilter.py``).

Prints, for one case (its bags, the last held out; discover's signals: speed timing and acceleration window as the
bench reads them, standstill rows out):

* per bag: speed (median and q90 of |omega_m|), temperature, and the rows near the transition;
* the tanh baseline's width eps by the CV profile on the raw columns and on the filtered equation, and the raw
  model's held-out RMSE and held-out mean residual at each width and at the simulator's width (``/sim/effects``,
  read here for the diagnosis only: nothing here feeds an estimator);
* with ``--stribeck``: the joint Stribeck shape (omega_s, delta, eps) profiled both ways, and the raw model's
  held-out RMSE at each.

    python bench/diag_width_filtered.py CASE_DIR [--stribeck]

CASE_DIR holds ``bags/*.mcap`` (``hdphm bench discover`` writes WORLD/EFFECT/bags).
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as B
    from hd_ground.discovery.core import Options, _lstsq, standstill_rows
    from hd_ground.discovery.prefilter import smooth_like_derivative
    from hd_twin.identify import BlockGram, Shape, fit_separable

    args = argv if argv is not None else sys.argv[1:]
    case = Path(args[0])
    stribeck = "--stribeck" in args
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    ds, ho = B.discover_dataset(bags)
    keep = ~standstill_rows(ds, Options().standstill_sigmas)[0]
    S, t, seg = ds.signals, ds.t, ds.segment
    win = float(ds.alpha_window.get("window_s", 0.02))
    hok, blk, bag = ho[keep], ds.block[keep], ds.bag[keep]
    fit = ~hok
    rows, hrows = np.flatnonzero(keep)[fit], np.flatnonzero(keep)[hok]
    w = S["omega_m"]
    print(f"speed lags {ds.speed_lags}; acceleration {ds.alpha_window}; fit rows {len(rows)}, held-out {len(hrows)}")
    for b in np.unique(bag):
        m = bag == b
        wb = np.abs(w[keep][m])
        tt = S["temperature"][keep][m] if "temperature" in S else np.full(m.sum(), np.nan)
        print(f"  bag {b}{' (held out)' if hok[m].all() else ''}: |omega_m| median {np.median(wb):.3g} q90 "
              f"{np.quantile(wb, 0.9):.3g} rad/s, temperature {np.median(tt):.1f} degC, rows with |omega_m| < 3 rad/s "
              f"{int((wb < 3).sum())}")
    try:
        truth = (B.read_truth(bags[0]) or {}).get("effects", {})
    except Exception:  # noqa: BLE001 (plant2's bags carry no /sim/effects of this form)
        truth = {}
    sm = truth.get("smooth_friction") or {}
    eps_true = sm.get("width") if sm.get("on") else None
    st = truth.get("stribeck_friction") or {}
    print(f"simulator (diagnosis only): width {eps_true}, Stribeck on {st.get('on')} omega_s {st.get('omega_s')} "
          f"delta {st.get('delta')}")
    scale = float(np.quantile(np.abs(w[rows]), 0.9))
    extra = [S["alpha_m"]] + ([S["alpha_m_dot"]] if "alpha_m_dot" in S and np.std(S["alpha_m_dot"]) > 0 else [])

    def full(sh):
        d = np.tanh(w / sh["eps"])
        c = [S["Q_red_over_N"], w, d]
        if "omega_s" in sh:
            c.append(np.exp(-(np.abs(w) / sh["omega_s"]) ** sh["delta"]) * d)
        return np.column_stack(c)

    def design(filtered: bool, at):
        def f(sh):
            M = full(sh)
            if filtered:
                M = smooth_like_derivative(M, t, seg, win)
            return np.column_stack(extra + [M[:, j] for j in range(M.shape[1])])[at]
        return f

    def held_out(sh) -> tuple[float, float, float]:
        X = design(False, rows)(sh)
        g = BlockGram(X, S["tau_m"][rows], blk[fit]).cv_sse().sum()
        r = S["tau_m"][hrows] - design(False, hrows)(sh) @ _lstsq(X, S["tau_m"][rows])
        return float(np.sqrt(np.mean(r ** 2))), float(r.mean()), float(np.sqrt(g / len(rows)))

    names = [f"x{j}" for j in range(len(extra) + 3)]
    yr, yf = S["tau_m"][rows], smooth_like_derivative(S["tau_m"], t, seg, win)[rows]
    eps_sh = Shape("eps", 0.05, 0.5 * scale, log=True, n_grid=12)
    print("tanh baseline (raw model scored on the held-out bag; CV = the raw columns' fit-block CV RMSE):")
    found = {}
    for lab, filt, y in (("raw profile", False, yr), ("filtered profile", True, yf)):
        f = fit_separable(y, design(filt, rows), names, blk[fit], [eps_sh])
        found[lab] = f.shape["eps"]
        h, mr, cv = held_out(f.shape)
        print(f"  {lab:17s} eps {f.shape['eps']:.4g} +- {f.shape_sd['eps']:.2g}: held-out {h:.5f} (mean residual "
              f"{mr:+.4f}), CV {cv:.5f}")
    if eps_true:
        h, mr, cv = held_out({"eps": eps_true})
        print(f"  {'simulator width':17s} eps {eps_true:.4g}: held-out {h:.5f} (mean residual {mr:+.4f}), CV {cv:.5f}")
    if stribeck:
        print("Stribeck (omega_s, delta, eps) jointly:")
        shapes = [Shape("omega_s", 0.05 * scale, scale, log=True, n_grid=8), Shape("delta", 0.3, 5.0, log=True, n_grid=5),
                  eps_sh]
        for lab, filt, y in (("raw profile", False, yr), ("filtered profile", True, yf)):
            f = fit_separable(y, design(filt, rows), names + ["dT"], blk[fit], shapes)
            h, mr, cv = held_out(f.shape)
            print(f"  {lab:17s} " + ", ".join(f"{k} {v:.4g} +- {f.shape_sd[k]:.2g}" for k, v in f.shape.items())
                  + f": held-out {h:.5f} (mean residual {mr:+.4f}), CV {cv:.5f}")
        if eps_true and st.get("on"):
            h, mr, cv = held_out({"eps": eps_true, "omega_s": st["omega_s"], "delta": st["delta"]})
            print(f"  {'simulator shape':17s}: held-out {h:.5f} (mean residual {mr:+.4f}), CV {cv:.5f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
