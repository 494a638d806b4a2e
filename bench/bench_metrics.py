"""PHM metrics: the same RUL histories scored by today's metrics and by another revision's, and speed vs progpy.

    hdphm bench metrics --extra [--old REV] [--virkler] [--battery [--regen-nu NU]]
                                [--eval-dir DIR --fleet DIR] [--particles N] [--json OUT]

* ``--virkler`` / ``--battery``: runs the real-data prognoses exactly as
  ``hdphm prognostic virkler`` / ``battery`` do (same defaults) and scores
  every unit's in-memory history twice: with ``hd_prognostic.metrics`` of this
  tree and with the one of git revision ``REV`` (read with ``git show``;
  default a459c52, the last before issue 17). The predictions are identical,
  so every difference is the metrics' own.
* ``--eval-dir DIR --fleet DIR``: the histories that ``hdphm prognostic eval``
  wrote (``rul_*.json``, quantile grid as samples) against the fleet's
  ``fleet_truth.json``, scored both ways.
* Always: time of the metrics progpy also computes (alpha-lambda beta x3, PH
  first entry, CRA; progpy convention) vs progpy's own functions on the same
  histories (ratio in the same run), if progpy is installed.

Prints per-aggregate ``key: old -> new`` (``moved`` marks differences).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hd_prognostic import metrics as M

KEYS = ("frac_in_cone_lambda_ge_0.5", "coverage_p5_p95", "relative_accuracy_lambda_0.5", "cra", "mae",
        "convergence", "pit_ks", "crps_mean", "ph_point", "ph_beta", "ph_point_sustained", "ph_beta_sustained")


def _old_module(rev: str):
    root = Path(__file__).resolve().parents[1]
    src = subprocess.run(["git", "-C", str(root), "show", f"{rev}:src/hd_prognostic/metrics.py"], check=True,
                         capture_output=True, text=True).stdout
    f = Path(tempfile.mkdtemp()) / "metrics_old.py"
    f.write_text(src)
    spec = importlib.util.spec_from_file_location("metrics_old", f)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _score_both(old, units: list[tuple], old_kw: dict | None = None) -> tuple[list, list]:
    """units: (name, hist, t_eol, kwargs)."""
    po, pn = [], []
    for name, h, eol, kw in units:
        s = h.samples or None
        po.append(old.score_history(h.rul_t, h.p50, h.p5, h.p95, eol, samples=s, **kw))
        pn.append(M.score_history(h.rul_t, h.p50, h.p5, h.p95, eol, samples=s, weights=h.sample_weights or None,
                                  rul_horizon=h.meta.get("rul_horizon"), **kw))
    return po, pn


def _report(title: str, names: list[str], po: list, pn: list) -> dict:
    ao, an = old_aggregate(po), M.aggregate(pn)
    if "prognostic_horizon" in ao:  # the old key: sustained form, of the samples when there were any
        ao["ph_beta_sustained" if "pit_ks" in ao else "ph_point_sustained"] = ao.pop("prognostic_horizon")
    print(f"\n== {title}: {len(pn)} units ==")
    for k in KEYS:
        o, n = ao.get(k), an.get(k)
        if o is None and n is None:
            continue
        moved = o is None or n is None or abs(o - n) > 5e-3
        print(f"  {k:30s} {_f(o)} -> {_f(n)}{'   moved' if moved else ''}")
    print(f"  alpha-lambda pass rate (point)  {ao.get('alpha_lambda_pass_rate')} -> "
          f"{an.get('alpha_lambda_point_pass_rate')}")
    if "alpha_lambda_beta_pass_rate" in an:
        print(f"  alpha-lambda pass rate (beta={pn[0]['beta']})   {an['alpha_lambda_beta_pass_rate']}")
    print(f"  infinite values capped: {sum(u.get('n_inf_capped', 0) for u in pn)}")
    per, shown = {}, 0
    for nm, o, n in zip(names, po, pn):
        per[nm] = {"old": {k: o.get(k) for k in ("cra", "relative_accuracy_lambda_0.5", "mae", "prognostic_horizon")},
                   "new": {k: n.get(k) for k in KEYS}}
        ch = [k for k in ("cra", "relative_accuracy_lambda_0.5", "mae") if abs(o[k] - n[k]) > 5e-3]
        if ch and shown < 8:
            shown += 1
            print(f"    {nm}: " + ", ".join(f"{k} {o[k]:.3f} -> {n[k]:.3f}" for k in ch))
    return {"old": ao, "new": an, "per_unit": per}


def old_aggregate(per: list) -> dict:
    keys = ["frac_in_cone_lambda_ge_0.5", "relative_accuracy_lambda_0.5", "cra", "convergence", "coverage_p5_p95",
            "mae", "pit_ks", "crps_mean", "prognostic_horizon"]
    out = {k: float(np.mean([u[k] for u in per if k in u and u[k] is not None and np.isfinite(u[k])]))
           for k in keys if any(k in u for u in per)}
    lam: dict = {}
    for u in per:
        for k, v in u.get("alpha_lambda", {}).items():
            lam.setdefault(k, []).append(v)
    out["alpha_lambda_pass_rate"] = {k: float(np.mean(v)) for k, v in lam.items()}
    return out


def _f(v) -> str:
    return "   -  " if v is None else f"{v:7.3f}"


def _speed(units: list[tuple]) -> None:
    try:
        from progpy.predictors import ToEPredictionProfile
        from progpy.uncertain_data import UnweightedSamples
    except ImportError:
        print("\n(progpy not installed: no speed comparison)")
        return
    units = [u for u in units if u[1].samples][:4]
    if not units:
        return
    lams = (0.25, 0.5, 0.75)

    def ours_one(h, eol):
        t = np.asarray(h.rul_t, float)
        sel = t < eol
        t, s = t[sel], [x for x, k in zip(h.samples, sel) if k]
        M.alpha_lambda(t, None, eol, None, 0.2, lams, samples=s, beta=0.5, convention="progpy")
        M.prognostic_horizon(t, eol, samples=s, alpha=0.05, beta=0.5, convention="progpy")
        sum(M._progpy_ra(ti, x, None, eol) for ti, x in zip(t, s))

    t0 = time.perf_counter()
    for _, h, eol, kw in units:
        ours_one(h, eol)
    ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _, h, eol, kw in units:
        prof = ToEPredictionProfile()
        for ti, s in zip(h.rul_t, h.samples):
            if ti < eol:
                prof.add_prediction(ti, UnweightedSamples([{"EOL": ti + v} for v in s]))
        gt = {"EOL": eol}
        t_p = min(prof.keys())
        for lam in lams:
            prof.alpha_lambda(gt, t_p + lam * (eol - t_p), 0.2, 0.5)
        prof.prognostic_horizon(lambda tte, g: {k: v >= 0.5 for k, v in tte.percentage_in_bounds(
            {k: [x - 0.05 * eol, x + 0.05 * eol] for k, x in g.items()}).items()}, gt)
        prof.cumulative_relative_accuracy(gt)
    theirs = time.perf_counter() - t0
    n = sum(len(u[1].samples) for u in units)
    print(f"\nspeed, the same metrics (alpha-lambda beta x3, PH beta first entry, CRA; progpy convention) on "
          f"{len(units)} histories ({n} predictions with {len(units[0][1].samples[0])} samples): ours {ours:.3f} s, "
          f"progpy {theirs:.3f} s, ratio {theirs / ours:.1f}x (building progpy's profile included)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench metrics", description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="a459c52", help="git revision whose metrics.py is the 'old' side (default a459c52: "
                    "the metrics before issue 17)")
    ap.add_argument("--virkler", action="store_true")
    ap.add_argument("--battery", action="store_true")
    ap.add_argument("--regen-nu", type=float, default=0.0)
    ap.add_argument("--particles", type=int, default=2000)
    ap.add_argument("--eval-dir", help="output folder of 'hdphm prognostic eval' (rul_*.json)")
    ap.add_argument("--fleet", help="the fleet folder of that evaluation (fleet_truth.json)")
    ap.add_argument("--json", help="write the comparison here")
    a = ap.parse_args(argv)
    old = _old_module(a.old)
    res, all_units = {}, []
    if a.eval_dir:
        if not a.fleet:
            print("error: --eval-dir needs --fleet (its fleet_truth.json gives the ends of life)", file=sys.stderr)
            return 2
        from hd_prognostic.tracking import RULHistory

        truth = json.loads((Path(a.fleet) / "fleet_truth.json").read_text())
        eol = {x["actuator_id"]: x["eol_mission"] for x in truth["actuators"]}
        units = []
        for f in sorted(Path(a.eval_dir).glob("rul_*.json")):
            h = RULHistory.from_json(json.loads(f.read_text()))
            if eol.get(h.unit) is not None:
                units.append((h.unit, h, float(eol[h.unit]), {"alpha": 0.2}))
        po, pn = _score_both(old, units)
        res["eval"] = _report(f"{a.eval_dir} (stored histories, quantile grid as samples)", [u[0] for u in units],
                              po, pn)
        all_units += units
    if a.virkler:
        from hd_prognostic.realdata import run_virkler

        r = run_virkler(n_particles=a.particles)
        units = [(str(k), u["history"], float(u["history"].meta["t_eol"]), {}) for k, u in r["units"].items()]
        po, pn = _score_both(old, units)
        res["virkler"] = _report("Virkler (hdphm prognostic virkler)", [u[0] for u in units], po, pn)
        all_units += units
    if a.battery:
        from hd_prognostic.realdata import run_battery

        r = run_battery(n_particles=a.particles, regen_nu=a.regen_nu)
        for frac in sorted({k.split("@")[1] for k in r["units"]}):
            units = [(k, u["history"], float(u["history"].meta["t_eol"]), {"t_p": 20.0})
                     for k, u in r["units"].items() if k.endswith("@" + frac)]
            po, pn = _score_both(old, units)
            res[f"battery@{frac}"] = _report(f"NASA battery, EOL {frac} (regen_nu {a.regen_nu:g})",
                                             [u[0] for u in units], po, pn)
            all_units += units
    _speed(all_units)
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
