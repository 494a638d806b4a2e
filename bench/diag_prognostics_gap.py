"""Where the life model loses in-cone fraction against the "in-cone bound" of ``hdphm bench prognostics`` (issue 12).

Diagnosis only: it reads each fleet's ``fleet_truth.json`` (the true wear path ``h`` per mission and ``h_fail``) to
build forecasts that know part of the truth; nothing here feeds a fit or a prognosis. For every failed unit the life
model is fitted leave-one-unit-out exactly as the bench does (the other units' HI histories and failure missions,
its defaults: 20 draws, path / threshold / noise by AIC, clock ``--exposure``) and its RUL median is scored in the
alpha = 0.2 cone for lambda >= 0.5, next to forecasts that each know more of the truth:

* ``wear bound``: the bench's column: the unit's true *future* wear path and the population's failure wear (median
  ``h_fail`` of the other units);
* ``wear now``: the true wear *now* and the population's failure wear, the future at the unit's past mean wear rate
  per mission (what the bound owes to knowing the future loads);
* ``own HI map``: the unit's own noise-free HI as a function of its wear (quadratic fit of its HI records on its true
  wear) with the true wear now and the past mean wear rate, failure when its HI rise over its offset reaches the
  population's (median over the other units of their HI rise at failure): a threshold in HI units, as the life model
  has;
* ``HI now``: the noise-free HI rise now (the same map), in units of the population's rise at failure, extrapolated
  along the fold's fitted path ``L ~ E^b`` at the unit's past mean exposure rate: the life model's state estimate
  replaced by the truth.

It also prints, per lambda bin, the fraction of the model's medians too late / too early (outside the cone) and the
error of the latent median ``L50`` against the noise-free HI rise over the fold's ``c``.

    python bench/diag_prognostics_gap.py --fleet smooth-cubic=SC --fleet hysteretic-robot=HR --out runs/gap \\
        [--cache runs/bench_prognostics/cache]     # feature cache of the bench (cache/NAME), optional
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

BINS = ((0.5, 0.75), (0.75, 0.9), (0.9, 1.01))
FORECASTS = ("model", "wear bound", "wear now", "own HI map", "HI now")


def _in_cone(p, rul):
    return (p >= 0.8 * rul) & (p <= 1.2 * rul)


def _first(path_ok, mi):
    j = np.flatnonzero(path_ok)
    return float(mi[j[0]]) if len(j) else float("nan")


def fleet_folds(fleet_dir: str, cache: Path | None, exposure: str, draws: int, seed: int) -> dict:
    """Leave-one-unit-out life-model predictions (bench defaults) with each unit's truth attached."""
    from hd_prognostic.evaluate import load_fleet
    from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory, attach_events, predict_history
    from hd_prognostic.pipeline import unit_history

    truth = json.loads((Path(fleet_dir) / "fleet_truth.json").read_text())
    ev = {a["actuator_id"]: UnitEvents(failure=float(a["eol_mission"])) for a in truth["actuators"]
          if a.get("eol_mission") is not None}
    fleet = load_fleet(fleet_dir, cache_dir=cache, progress=False, workers=1)
    units = [unit_history(a, "HF_MTW_IF", exposure) for a in fleet]
    attach_events(units, ev)
    T = {a["actuator_id"]: a for a in truth["actuators"]}
    out = {}
    for i, u in enumerate(units):
        if u.unit not in ev:
            continue
        m = LifeModel.fit([v for j, v in enumerate(units) if j != i], exposure=exposure, feature="HF_MTW_IF",
                          n_draws=draws, seed=seed, threshold="auto", path="auto", failure_at="auto",
                          exposure_rate="mean", exposure_spread="renewal+rate", noise="auto")
        test = UnitHistory(u.unit, u.t.copy(), u.y.copy(), u.E.copy(), u.discrete, u.E_next, u.hours_per_step,
                           UnitEvents())
        h = predict_history(m, test, n_samples=1000, seed=seed)
        a = T[u.unit]
        out[u.unit] = dict(t=np.array(h.rul_t), p50=np.array(h.p50), L50=np.array([s[0] for s in h.state_mean]),
                           y=u.y.copy(), E=u.E.copy(), eol=ev[u.unit].failure, h_fail=float(a["params"]["h_fail"]),
                           h=np.array([x["h"] for x in a["missions"]], float),
                           mi=np.array([x["mission_index"] for x in a["missions"]], float),
                           b=m.b, c=float(m.theta["c"]), label=f"{m.path} {m.threshold}, noise {m.fit_info.get('noise')}")
    return out


def decompose(R: dict) -> dict:
    """In-cone fraction (lambda >= 0.5 and per lambda bin) of the model and of the truth-informed forecasts."""
    hmap = {}
    for u, r in R.items():  # the unit's noise-free HI as a function of its wear (scoring code: truth)
        hy = np.interp(r["t"], r["mi"], r["h"])
        ok = np.isfinite(r["y"])
        hmap[u] = np.polyfit(hy[ok] / r["h_fail"], r["y"][ok], 2)
    g = lambda u, h: np.polyval(hmap[u], np.asarray(h) / R[u]["h_fail"])  # noqa: E731
    rise = {u: float(g(u, r["h_fail"]) - g(u, 0.0)) for u, r in R.items()}  # HI rise at failure
    res = {}
    for u, r in R.items():
        t, eol, E, p50 = r["t"], r["eol"], r["E"], r["p50"]
        others = [v for v in R if v != u]
        pop_h = float(np.median([R[v]["h_fail"] for v in others]))
        pop_rise = float(np.median([rise[v] for v in others]))
        # the true wear path, continued past its last mission at the last 10 missions' rate
        k = min(10, len(r["h"]) - 1)
        rt = (r["h"][-1] - r["h"][-1 - k]) / max(r["mi"][-1] - r["mi"][-1 - k], 1.0)
        ext = np.arange(1, 1000, dtype=float)
        hw = np.concatenate([r["h"], r["h"][-1] + rt * ext])
        mi = np.concatenate([r["mi"], r["mi"][-1] + ext])
        h_now = np.interp(t, mi, hw)
        wrate = h_now / np.maximum(t - mi[0], 1.0)  # past mean wear per mission
        erate = (E - E[0]) / np.maximum(t - t[0], 1.0)  # past mean exposure per mission
        tau = np.arange(0, 1000, dtype=float)
        f = {"model": p50, "wear bound": _first(hw >= pop_h, mi) - t,
             "wear now": np.ceil(np.maximum(pop_h - h_now, 0) / np.maximum(wrate, 1e-300) - 1e-9),
             "own HI map": np.array([_first(g(u, h_now[j] + wrate[j] * tau) - g(u, 0.0) >= pop_rise * (1 - 1e-9), tau)
                                     for j in range(len(t))])}
        L_true = (g(u, h_now) - g(u, 0.0)) / pop_rise
        Ef = E * (1.0 / np.clip(L_true, 1e-9, 1.0)) ** (1.0 / r["b"])
        f["HI now"] = np.ceil(np.maximum(Ef - E, 0.0) / np.maximum(erate, 1e-300) - 1e-9)
        lam = (t - t[0]) / (eol - t[0])
        rul = eol - t
        sel = (lam >= 0.5) & (t < eol)
        row = {"h_fail / pop": r["h_fail"] / pop_h, "HI rise at failure / pop": rise[u] / pop_rise, "fit": r["label"],
               "h_fail": r["h_fail"], "HI rise at failure": rise[u]}
        for name, p in f.items():
            row[name] = float(np.mean(_in_cone(p, rul)[sel]))
        L_err = np.abs(r["L50"] - (g(u, h_now) - g(u, 0.0)) / r["c"])
        for a, b in BINS:
            s = (lam >= a) & (lam < b) & (t < eol)
            row[f"bin {a}-{b}"] = {"n": int(s.sum()), **{n: float(np.mean(_in_cone(p, rul)[s])) for n, p in f.items()},
                                   "late": float(np.mean(p50[s] > 1.2 * rul[s])),
                                   "early": float(np.mean(p50[s] < 0.8 * rul[s])),
                                   "|L50 - L|": float(np.median(L_err[s])),
                                   "cone half-width 0.2 (1 - L)": float(np.median(0.2 * (1 - L_true[s])))}
        res[u] = row
    return res


def report(name: str, res: dict) -> str:
    lines = [f"== {name}", "unit | h_fail/pop | HI rise at failure/pop | " + " | ".join(FORECASTS) + " | fit"]
    for u, r in res.items():
        lines.append(f"{u} | {r['h_fail / pop']:.3f} | {r['HI rise at failure / pop']:.3f} | "
                     + " | ".join(f"{r[n]:.2f}" for n in FORECASTS) + f" | {r['fit']}")
    lines.append("mean | | | " + " | ".join(f"{np.mean([r[n] for r in res.values()]):.2f}" for n in FORECASTS))
    cv = lambda v: float(np.std(np.log(v), ddof=1))  # noqa: E731
    lines.append(f"scatter over the units (sd of log): h_fail {cv([r['h_fail'] for r in res.values()]):.3f}, "
                 f"HI rise at failure {cv([r['HI rise at failure'] for r in res.values()]):.3f}")
    for a, b in BINS:
        k = f"bin {a}-{b}"
        rows = [r[k] for r in res.values() if r[k]["n"]]
        m = {n: np.mean([x[n] for x in rows]) for n in rows[0] if n != "n"}
        lines.append(f"lambda [{a}, {b}): " + ", ".join(f"{n} {m[n]:.2f}" for n in FORECASTS)
                     + f" | model late {m['late']:.2f} early {m['early']:.2f} | |L50 - L| {m['|L50 - L|']:.3f}, "
                       f"cone half-width in L {m['cone half-width 0.2 (1 - L)']:.3f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="diag_prognostics_gap", description=__doc__.split("\n")[0])
    ap.add_argument("--fleet", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--cache", default=None, help="feature cache root (the bench's OUT/cache): NAME/ under it")
    ap.add_argument("--exposure", default="load", choices=("missions", "hours", "load"))
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/diag_prognostics_gap")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    allres = {}
    for spec in args.fleet:
        name, d = spec.split("=", 1)
        cache = Path(args.cache) / name if args.cache else out / "cache" / name
        res = decompose(fleet_folds(d, cache, args.exposure, args.draws, args.seed))
        allres[name] = res
        print(report(name, res), flush=True)
    (out / "diag_prognostics_gap.json").write_text(json.dumps(allres, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
