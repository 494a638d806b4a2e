"""Diagnosis of a Q_red case where a smooth function of a short-stroke output angle and the cubic torsion law are two
readings of one effect (issue 10; smooth-cubic kinematic error, seeds 3100 and 1300).

Over a short output stroke the load, hence the twist w, follows theta_f, so ``unknown(theta_f)`` (p0 + p1 u + p2 u^2 +
p3 u^3, u = theta_f - median) reads most of k3 w^3. This script puts the models side by side on discover's rows and
twist (theta_f smoothed over the report's window): baseline B = K w + c w' + alpha_f; U = unknown(theta_f) (centre:
the fit rows' median, as discover builds it); NLS = w^3; KE2 = sin / cos 2 theta_m; the ripple variants PDS1/PDS3
(w sin / cos k theta_m). Each row: the held-out bag's RMSE and the fit blocks' leave-one-block-out CV
(``diag_models.ModelTable``), the jackknife Wald of each group in the joint models (what discover's identification rule
reads, ``core._BlockGram.jackknife_wald`` against the 3-sigma chi^2 quantile), and how much of w^3 (beyond the
baseline) the angle's polynomial explains on the fit rows. Diagnosis only: nothing here feeds an estimator.

    python bench/diag_confounded_qred.py CASE_DIR [REPORT_JSON]

CASE_DIR: a bench_discover case (``bags/*.mcap``, the last bag held out; ``discovery/report.json`` by default).
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
    from hd_ground.discovery.core import _BlockGram, _wald_threshold
    from hd_ground.discovery.data import with_smoothed_twist

    args = list(argv if argv is not None else sys.argv[1:])
    case = Path(args[0])
    rep = json.loads(Path(args[1] if len(args) > 1 else case / "discovery" / "report.json").read_text())
    s0 = next(x for x in rep["signals"] if x["signal"] == "Q_red")
    tw = int(rep.get("twist_window_samples", 0))
    ds0, ho = B.discover_dataset(sorted(glob.glob(str(case / "bags" / "*.mcap"))))
    fit = ~ho
    ds = with_smoothed_twist(ds0, tw) if tw else ds0
    s, blk = ds.signals, ds.block
    y = s["Q_red"]
    print(f"twist window {tw}; discover's terms: "
          + ", ".join(f"{t['name']}({t['variable']}, {t.get('order')})" for t in s0["terms"]))
    for b in np.unique(ds.bag):
        m = ds.bag == b
        print(f"  bag {b}{' (held out)' if ho[m].all() else ''}: theta_f [{s['theta_f'][m].min():+.3f}, "
              f"{s['theta_f'][m].max():+.3f}] rad, w [{s['windup'][m].min():+.2e}, {s['windup'][m].max():+.2e}] rad")
    u = s["theta_f"] - float(np.median(s["theta_f"][fit]))
    base = [s["windup"], s["windup_dot"], s["alpha_f"]]
    U = [np.ones_like(u), u, u**2, u**3]
    NLS = [s["windup"] ** 3]
    KE2 = [np.sin(2 * s["theta_m"]), np.cos(2 * s["theta_m"])]
    pds = {k: [s["windup"] * np.sin(k * s["theta_m"]), s["windup"] * np.cos(k * s["theta_m"])] for k in (1, 3)}
    T = ModelTable(y, fit, ho, blk, width=30, digits=4)
    T.report("B", base)
    for name, cols, ref in [("B + U", U, "B"), ("B + NLS", NLS, "B"), ("B + KE2", KE2, "B"),
                            ("B + U + KE2", U + KE2, "B + U"), ("B + KE2 + NLS", KE2 + NLS, "B + U + KE2"),
                            ("B + U + KE2 + NLS", U + KE2 + NLS, "B + KE2 + NLS"),
                            ("B + KE2 + NLS + PDS1", KE2 + NLS + pds[1], "B + KE2 + NLS"),
                            ("B + KE2 + NLS + PDS3", KE2 + NLS + pds[3], "B + KE2 + NLS")]:
        T.report(name, base + cols, ref)
    nb = len(base)

    def wald(groups: list[list[np.ndarray]], which: int) -> str:
        cols = base + [c for g in groups for c in g]
        X = np.column_stack(cols)
        g = _BlockGram(X[fit], y[fit], blk[fit])
        start = nb + sum(len(gg) for gg in groups[:which])
        test = list(range(start, start + len(groups[which])))
        return f"{g.jackknife_wald(list(range(X.shape[1])), test):8.2f} (3-sigma threshold {_wald_threshold(len(test), 3.0):.2f})"

    print("jackknife Wald on the fit blocks:")
    print("  U   in B + U + KE2         ", wald([U, KE2], 0))
    print("  NLS in B + KE2 + NLS       ", wald([KE2, NLS], 1))
    print("  U   in B + U + KE2 + NLS   ", wald([U, KE2, NLS], 0))
    print("  NLS in B + U + KE2 + NLS   ", wald([U, KE2, NLS], 2))
    print("  PDS1 in B + KE2 + NLS + PDS1", wald([KE2, NLS, pds[1]], 2))
    print("  PDS3 in B + KE2 + NLS + PDS3", wald([KE2, NLS, pds[3]], 2))
    X0 = np.column_stack(base)[fit]
    w3 = NLS[0][fit]
    r0 = w3 - X0 @ np.linalg.lstsq(X0, w3, rcond=None)[0]
    X1 = np.column_stack(base + U)[fit]
    r1 = w3 - X1 @ np.linalg.lstsq(X1, w3, rcond=None)[0]
    print(f"w^3 beyond the baseline explained by the theta_f polynomial on the fit rows: {1 - r1.var() / r0.var():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
