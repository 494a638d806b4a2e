"""Diagnosis of the logged speed's re-timing window (issue 10, branch disc31 pass): what the derivative window of
``omega + tau omega'`` (``hd_twin.speedtiming``) does to the speed, to the tau_m baseline's fit-bag CV error, and to
the friction shape discovery profiles, on one case's bags (the last held out, as the bench).

For each window (default: 20 ms, the default, then 5, 9, 17 and 33 samples at the log rate) the case's signals are
built as discover builds them (the delays identified at that window, discover's speed-timing and acceleration choices
made on the fit bags, ``bench_discover.discover_dataset`` with the window forced) and it prints:

* the delays, and the speed's consistency with its own angle: RMS of theta[k+1] - theta[k] - dt (omega[k] +
  omega[k+1]) / 2 over dt (rad/s; data only: a re-timed speed that lags a reversal fails it, its noise too);
* the plain tau_m baseline's fit-block CV RMSE (what ``core.choose_retime_window`` decides on);
* with ``--stribeck``: ``diag_width_filtered``'s joint Stribeck profile (omega_s, delta, eps) on the raw and
  filtered columns and the simulator's shape (``/sim/effects``, read for the diagnosis only), each with the
  held-out RMSE and the fit-block CV.

    python bench/diag_retime_window.py CASE_DIR [--stribeck] [--windows 20,5,9]   (windows in ms)
    python bench/diag_retime_window.py CASE_DIR --choice-only   (discover's choice with --retime-window identify:
                                                                  whether the gate fires on the case, and why)

CASE_DIR holds ``bags/*.mcap`` (``hdphm bench discover`` writes WORLD/EFFECT/bags). Diagnosis only: nothing here
feeds an estimator.
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as B
    import diag_width_filtered as W
    from hd_bag import read_mission
    from hd_ground.discovery.core import (Options, baseline_cv_folds, choose_alpha_window, choose_retime_window,
                                          choose_speed_timing, standstill_rows)
    from hd_ground.discovery.data import dataset_from_missions

    args = argv if argv is not None else sys.argv[1:]
    case = Path(args[0])
    stribeck = "--stribeck" in args
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    names = [str(b) for b in bags]
    ms = [read_mission(b) for b in bags]
    dt = float(np.median(np.diff(ms[0].t)))
    if "--windows" in args:
        wins = [float(x) * 1e-3 for x in args[args.index("--windows") + 1].split(",")]
    else:
        wins = [0.02] + [k * dt for k in (5, 9, 17, 33) if abs(k * dt - 0.02) >= 0.5 * dt]

    ds0 = dataset_from_missions(ms, names)
    ho0 = ds0.bag == len(bags) - 1
    if ds0.speed_lags:
        ds0, st = choose_speed_timing(dataset_from_missions(ms, names, retime_speeds=False), ds0, ho0)
        print(st)
    if not ds0.speed_lags:
        print("speeds used as logged: the re-timing window is not tried (gate cannot fire)")
    else:
        print(choose_retime_window(lambda win: dataset_from_missions(ms, names, retime_window_s=win), ds0, ho0,
                                   Options(retime_window="identify"))[1])
    if "--choice-only" in args:
        return 0

    def forced(win):
        def discover_dataset(_bags):
            ds = dataset_from_missions(ms, names, retime_window_s=win)
            ho = ds.bag == len(bags) - 1
            if ds.speed_lags:
                ds = choose_speed_timing(dataset_from_missions(ms, names, retime_speeds=False), ds, ho)[0]
            ds = choose_alpha_window(lambda w, timing, re=bool(ds.speed_lags): dataset_from_missions(
                ms, names, retime_speeds=re, alpha_window_s=w, alpha_timing=timing, retime_window_s=win), ds, ho)[0]
            return ds, ho
        return discover_dataset

    for win in wins:
        ds, ho = forced(win)(bags)
        still = standstill_rows(ds, Options().standstill_sigmas)[0]
        base = baseline_cv_folds(ds, ho, ~still)
        w, th, seg = ds.signals["omega_m"], ds.signals["theta_m"], ds.segment
        same = (seg[1:] == seg[:-1]) & (ds.bag[1:] == ds.bag[:-1])
        e = (np.diff(th) - np.diff(ds.t) * 0.5 * (w[1:] + w[:-1]))[same] / dt
        per_bag = [float(np.sqrt(np.mean(e[ds.bag[1:][same] == b] ** 2))) for b in np.unique(ds.bag)]
        print(f"== re-timing window {win * 1e3:.3g} ms: delays "
              f"{ {k: round(v * 1e3, 4) for k, v in ds.speed_lags.items()} } ms (empty: as logged); acceleration "
              f"{ds.alpha_window or 'default'}; speed vs angle RMS per bag "
              f"{' '.join(f'{x:.4f}' for x in per_bag)} rad/s; tau_m baseline fit-block CV "
              f"{base[1] if base else float('nan'):.5f} N*m")
        if stribeck:
            B.discover_dataset = forced(win)
            W.main([str(case), "--stribeck"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
