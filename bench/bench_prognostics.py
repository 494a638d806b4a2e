"""Benchmark: the life model fitted from operator records, leave-one-unit-out, per dataset.

For every dataset and every held-out unit: fit the life model on the *other* units' health-indicator
histories and events (failures / censoring) only (``--draws`` posterior parameter draws per fit), predict the
held-out unit's RUL at every record, score it against its failure time (in-cone alpha = 0.2 for lambda >= 0.5,
P5-P95 coverage, CRA, CRPS). In the same run: the UKF on the same fitted model (one filter per draw), the plug-in
point estimate of the same fit (maximum-likelihood parameters only: the model before the parameter draws), and
today's reference model (simulated fleets: the particle filter
calibrated on the training units' *wear truth* from /sim/health, an upper reference an operator cannot
have; NASA / Virkler: the exponential-fade / Paris-law particle filters of ``realdata.py``).

Datasets (each optional): simulated fleets (``--fleet NAME=DIR``, their ``fleet_truth.json`` gives the
failure missions, written as an events file: what an operator records), NASA cells (``--nasa DIR``, failure =
capacity <= 80 % of rated; 70 % leaves 1 failure in some training folds), Virkler (``--virkler DIR``). The
failure-time likelihood follows each dataset's failure definition (``--failure-at auto``,
``lifemodel.failure_at_rule``): a recorded crossing of a known level for NASA (1.6 Ah) and Virkler (49.8 mm),
found-failed intervals for the bag fleets.
With ``--inspect-every K`` (and/or ``--inspect-at-failure``) the events file of a simulated fleet also carries what an
overhaul shop measures (``--inspect-quantity lost_motion`` [rad] or ``wear_depth`` [m], from the truth plus the gauge's
noise ``--inspect-noise``; :func:`shop_inspections`): every unit's inspections enter its fold's fit, and the held-out
unit's own inspections up to each prediction time enter its prognosis (its failure stays unknown).
The degradation clock of the simulated fleets is chosen by maximum likelihood on the fleet named by
``--dev`` (all its units) and then fixed for every other fleet: no choice is made on the scored units.

    hdphm bench prognostics --extra --fleet dev=DIR --fleet scored=DIR --fleet smooth-cubic=DIR ... --dev dev \
        --events-fleet plant2=DIR --nasa DIR --virkler DIR --virkler-every 2 --out runs/bench_prognostics
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from hd_sim.plant import ARCMIN, wear_backlash

KEYS = ("frac_in_cone_lambda_ge_0.5", "coverage_p5_p95", "cra", "crps_mean")


def _score(hist, eol, samples=True):
    from hd_prognostic import metrics as M

    return M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, float(eol), alpha=0.2,
                           samples=hist.samples if samples and hist.samples else None)


def _row(ms):
    out = {}
    for k in KEYS:
        v = [m[k] for m in ms if k in m and m[k] is not None and np.isfinite(m[k])]
        out[k] = float(np.mean(v)) if v else float("nan")
    out["n"] = len(ms)
    return out


def _louo(units, eols, exposure, time_unit, feature, samples, seed, progress, label, level=None):
    """Leave-one-unit-out: life model (grid posterior) and UKF on it; units with a failure are scored."""
    from hd_prognostic.lifemodel import LifeModel, UnitEvents

    def fold(i):
        u = units[i]
        t0 = time.perf_counter()
        train = [v for j, v in enumerate(units) if j != i]
        m = LifeModel.fit(train, exposure=exposure, feature=feature, time_unit=time_unit, n_draws=DRAWS[0],
                          seed=seed, threshold=THRESHOLD[0], failure_level=level,
                          path=PATH[0], failure_at=FAILURE_AT[0], exposure_rate=RATE[0],
                          exposure_spread=SPREAD[0], noise=NOISE[0], scale_prior=SCALE_PRIOR[0],
                          hi_gain=GAIN[0])
        test = _copy_unit(u)
        test.events = UnitEvents(inspections=list(u.events.inspections))  # its end of life is not known
        sg, su, sp = _predict_all(m, test, eols[u.unit], samples, seed)
        sg["threshold"] = _label(m)
        sg.update(_noise_fields(m))
        if progress:
            print(f"  {label} {u.unit}: EOL {eols[u.unit]:g}, life model in-cone {sg['frac_in_cone_lambda_ge_0.5']:.2f}"
                  f" cov {sg['coverage_p5_p95']:.2f} CRA {sg['cra']:.2f} | UKF {su['frac_in_cone_lambda_ge_0.5']:.2f}"
                  f" / {su['coverage_p5_p95']:.2f} | plug-in {sp['frac_in_cone_lambda_ge_0.5']:.2f} / "
                  f"{sp['coverage_p5_p95']:.2f} (ESS {m.fit_info['parameter_uncertainty'].get('ess', 0):.0f}, "
                  f"threshold {m.threshold}{_noise_txt(m)})"
                  f"  [{time.perf_counter() - t0:.1f} s]", flush=True)
        return sg, su, sp

    res = _run_folds(fold, [i for i, u in enumerate(units) if u.events.failure is not None])
    return [r[0] for r in res], [r[1] for r in res], [r[2] for r in res]


def _noise_fields(m) -> dict:
    """A noise="auto" fit's record for the fold's row: the noise kept, the level fit's regularity and the AICs."""
    fi = m.fit_info
    out = {k: fi[k] for k in ("hi_gain", "gain_aic") if k in fi}
    if "log_sg" in m.theta:
        out["s_g"] = float(np.exp(m.theta["log_sg"]))
    if "noise_rule" not in fi:
        return out
    return dict(out, noise=fi["noise"], noise_rule=fi["noise_rule"], noise_aic=fi["noise_aic"])


def _noise_txt(m):
    """', noise level (regular)' for a noise="auto" fit: the noise kept and whether the level fit was regular."""
    r = m.fit_info.get("noise_rule")
    g = (f", HI gain {m.fit_info['hi_gain']}" + (f" (s_g {np.exp(m.theta['log_sg']):.3f})" if "log_sg" in m.theta
                                                 else "")) if "hi_gain" in m.fit_info else ""
    if r is None:
        return g
    return f", noise {m.fit_info['noise']}" + ("" if r["regular"] else f" (level fit irregular: {r['reason']})") + g


def _label(m):
    """Path, threshold and failure-time likelihood of a fold's fit, e.g. 'paris observable (crossing, fitted level)'."""
    lab = m.threshold if m.path == "power" else f"{m.path} {m.threshold}"
    if m.fit_info.get("failure_at") == "crossing":  # the failure level fixed at its definition or fitted
        lab += f" (crossing, {m.fit_info.get('level', 'fixed')} level)" if m.fit_info.get("level") else " (crossing)"
    return lab


JOBS = [1]  # processes for the leave-one-unit-out folds (--jobs)


def _run_folds(fold, items):
    """``[fold(x) for x in items]``, in ``JOBS[0]`` forked processes when > 1 (each fold is seeded on its own, so
    the results are those of the sequential loop, in the same order; progress lines interleave)."""
    jobs = min(JOBS[0], len(items))
    if jobs <= 1:
        return [fold(x) for x in items]
    import multiprocessing as mp
    import pickle
    import tempfile

    ctx = mp.get_context("fork")  # the fold closure is not pickled: each child runs its share and writes the results
    tmp = Path(tempfile.mkdtemp(prefix="bench_prog_folds_"))

    def child(k):
        out = {x: fold(x) for x in items[k::jobs]}
        (tmp / f"{k}.pkl").write_bytes(pickle.dumps(out))

    procs = [ctx.Process(target=child, args=(k,)) for k in range(jobs)]
    for pr in procs:
        pr.start()
    for pr in procs:
        pr.join()
    got = {}
    for k, pr in enumerate(procs):
        f = tmp / f"{k}.pkl"
        if pr.exitcode != 0 or not f.is_file():
            raise RuntimeError(f"bench prognostics: fold process {k} failed (exit code {pr.exitcode})")
        got.update(pickle.loads(f.read_bytes()))
        f.unlink()
    tmp.rmdir()
    return [got[x] for x in items]


DRAWS = [20]  # posterior parameter draws per fit (--draws)
PATH = ["auto"]  # latent path family (--path; auto: power law or crack-growth shape by AIC per fit)
THRESHOLD = ["auto"]  # where the failure threshold sits (--threshold; auto: maximum likelihood per fit)
SPREAD = ["renewal+rate"]  # the future exposure's variability in the prognosis (--exposure-spread; LifeModel.fit)
RATE = ["mean"]  # how the prognosis extrapolates a unit's exposure (--exposure-rate; UnitHistory.rate)
SCALE_PRIOR = ["uniform"]  # prior of the between-unit scales in the parameter draws (--scale-prior; LifeModel.fit)
GAIN = ["shared"]  # HI gain (--hi-gain; LifeModel.fit: one for all units, per unit, or by AIC per fit)
NOISE = ["auto"]  # HI noise model (--noise; LifeModel.fit: constant, level-dependent, or by AIC per fit)
FAILURE_AT = ["auto"]  # failure-time likelihood (--failure-at; auto: lifemodel.failure_at_rule, the definition's)


def _predict_all(m, test, eol, samples, seed):
    """Scores of the life model (posterior predictive over the parameter draws), the UKF on the same model
    (one filter per draw) and the plug-in point estimate (the maximum-likelihood parameters alone, the
    threshold law widened to its Student-t predictive: the model before the parameter draws)."""
    from hd_prognostic.lifemodel import LifeModel, predict_history

    plug = LifeModel(m.theta, m.E_ref, m.exposure, m.feature, m.inspections, m.fit_info, m.time_unit)
    out = []
    for model, method in ((m, "grid"), (m, "ukf"), (plug, "grid")):
        h = predict_history(model, test, n_samples=samples, seed=seed, method=method)
        sc = _score(h, eol)
        sc["unit"] = test.unit
        out.append(sc)
    return out


def _copy_unit(u):
    from hd_prognostic.lifemodel import UnitHistory

    return UnitHistory(u.unit, u.t.copy(), u.y.copy(), u.E.copy(), u.discrete, u.E_next, u.hours_per_step,
                       u.events, list(u.notes))


def sim_fleet(name, fleet_dir, out, exposure, args):
    """Events from fleet_truth.json (failure missions), histories from contract topics, LOUO; the
    wear-truth-calibrated PF as the upper reference."""
    from hd_prognostic.evaluate import load_fleet
    from hd_prognostic.pipeline import fit_population, prognose, unit_history
    from hd_prognostic.lifemodel import UnitEvents, attach_events, write_events

    truth = json.loads((Path(fleet_dir) / "fleet_truth.json").read_text())
    ev = {a["actuator_id"]: UnitEvents(failure=float(a["eol_mission"])) for a in truth["actuators"]
          if a.get("eol_mission") is not None}
    if args.inspect_every or args.inspect_at_failure:  # the overhaul shop's gauge (scoring side: reads the truth)
        ev = shop_inspections(truth, ev, args.inspect_every, args.inspect_quantity, args.inspect_noise,
                              args.inspect_at_failure, args.seed)
    write_events(out / f"{name}_events.csv", ev)
    fleet = load_fleet(fleet_dir, cache_dir=out / "cache" / name, progress=False, workers=args.workers)
    res = {}
    if exposure is None:
        from hd_prognostic.lifemodel import fit_best

        cands = {}
        for e in ("missions", "hours", "load"):
            us = [unit_history(a, args.feature, e) for a in fleet]
            attach_events(us, ev)
            cands[e] = us
        best = fit_best(cands, feature=args.feature, n_draws=0, threshold=THRESHOLD[0], path=PATH[0])
        exposure = best.exposure
        res["exposure_choice"] = best.fit_info["exposure_candidates"]
        print(f"{name}: exposure by maximum likelihood on all of {name}: {exposure} "
              f"({json.dumps(best.fit_info['exposure_candidates'], default=float)})", flush=True)
    units = [unit_history(a, args.feature, exposure) for a in fleet]
    attach_events(units, ev)
    eols = {k: v.failure for k, v in ev.items()}
    g, u, pl = _louo(units, eols, exposure, "mission", args.feature, args.samples, args.seed, True, name)
    res.update({"exposure": exposure, "life": g, "ukf": u, "plugin": pl})
    ref = []
    if not args.no_reference:
        for a in fleet:
            if a.actuator_id not in eols:
                continue
            train = [b for b in fleet if b.actuator_id != a.actuator_id]
            obs = fit_population(train)
            h = prognose(a, obs, n_particles=args.particles, seed=args.seed)
            s = _score(h, a.eol_mission())
            s["unit"] = a.actuator_id
            ref.append(s)
    res["reference"] = ref
    res["reference_name"] = "wear-truth-calibrated PF (fit_population on /sim/health of the training units)"
    res["bound"] = threshold_bound(truth, eols)
    return res, exposure


#: quantity -> (unit, default measurement sd in SI): the shop's gauge resolution / repeatability
#: (src/hd_prognostic/README.md, "What inspections at overhaul buy"): lost motion 0.1 arcmin (a lost-motion
#: test rig's repeatability; its encoder resolves ~1 arcsec), wear depth 1 um (tooth-profile CMM)
SHOP_QUANTITIES = {"lost_motion": ("rad", 0.1 * ARCMIN), "wear_depth": ("m", 1.0e-6)}


def shop_value(params: dict, mission: dict, quantity: str) -> float:
    """The true value of ``quantity`` at the start of one mission, from the simulator's truth (scoring code).
    ``wear_depth``: mean flank wear h = (h+ + h-)/2 [m]; ``lost_motion``: the angular backlash at the output,
    ``max(0, h+ + h- - 2 delta_0) / cos(alpha_p) / r_m`` [rad] (PHYSICS.md 4: the gap once the preload is worn
    through; the elastic part of a lost-motion reading is wear-independent and left out)."""
    hp, hm = float(mission["h_plus"]), float(mission["h_minus"])
    if quantity == "wear_depth":
        return 0.5 * (hp + hm)
    if quantity == "lost_motion":
        return wear_backlash(params, hp, hm) / float(params["r_m"])
    raise ValueError(f"inspection quantity {quantity!r} is not one of {', '.join(SHOP_QUANTITIES)}")


def shop_inspections(truth: dict, events: dict, every: int, quantity: str, noise: float | None,
                     at_failure: bool = False, seed: int = 0) -> dict:
    """An operator's events with overhaul inspections added: ``quantity`` measured at missions every, 2 every, ...
    before each unit's failure (units in service: up to their last mission) and, with ``at_failure``, at the
    teardown of a failed unit (its failure mission), each value = truth + N(0, noise^2) (``noise`` None: the
    quantity's default gauge sd, :data:`SHOP_QUANTITIES`). Seeded per unit (same values for the same seed)."""
    from hd_prognostic.lifemodel import UnitEvents

    sd = SHOP_QUANTITIES[quantity][1] if noise is None else float(noise)
    out = {}
    for k, a in enumerate(truth["actuators"]):
        aid = a["actuator_id"]
        old = events.get(aid, UnitEvents())
        by_m = {int(m["mission_index"]): m for m in a["missions"]}
        end = int(a["eol_mission"]) if a.get("eol_mission") is not None else max(by_m) + 1
        ms = list(range(every, end, every)) if every else []
        if at_failure and a.get("eol_mission") is not None:
            ms.append(end)
        rng = np.random.default_rng([seed, 9173, k])
        ins = list(old.inspections)
        for m in ms:
            if m in by_m:
                ins.append((float(m), quantity, shop_value(a["params"], by_m[m], quantity) + sd * rng.standard_normal()))
        out[aid] = UnitEvents(failure=old.failure, removal=old.removal, inspections=ins)
    return out


def threshold_bound(truth, eols):
    """In-cone fraction (alpha 0.2, lambda >= 0.5) of a forecast that knows each unit's *true* future wear path
    and only the population's failure wear (median h_fail of the other units): what a population-level
    threshold allows at best (scoring code: reads the simulator's truth)."""
    from hd_prognostic import metrics as M

    acts = [a for a in truth["actuators"] if a["actuator_id"] in eols]
    hf = {a["actuator_id"]: float(a["params"]["h_fail"]) for a in acts}
    out = {}
    for a in acts:
        aid = a["actuator_id"]
        pop = float(np.median([v for k, v in hf.items() if k != aid]))
        h = np.array([m["h"] for m in a["missions"]], float)
        mi = np.array([m["mission_index"] for m in a["missions"]], float)
        i = np.flatnonzero(h >= pop)
        if len(i):
            tf = mi[i[0]]
        else:  # extrapolate the last 10 missions' wear rate
            r = max((h[-1] - h[-11]) / 10.0, 1e-30) if len(h) > 11 else max(h[-1] / max(mi[-1], 1), 1e-30)
            tf = mi[-1] + np.ceil((pop - h[-1]) / r)
        eol = eols[aid]
        t = mi[mi < eol]
        p = tf - t
        out[aid] = M.score_history(t, p, p, p, eol)["frac_in_cone_lambda_ge_0.5"]
    return out


def events_fleet(name, fleet_dir, exposure, args):
    """A fleet of bags with the operator's own ``events.csv`` (e.g. the independent plant's fleet: failures
    and inspections); scored against the failures in that file. No wear-truth reference (no /sim topics)."""
    from hd_prognostic.pipeline import load_fleet_histories, unit_history
    from hd_prognostic.lifemodel import attach_events, read_events

    ev = read_events(Path(fleet_dir) / "events.csv")
    acts, _ = load_fleet_histories(fleet_dir, args.feature, "missions", cache_dir=Path(args.out) / "cache" / name,
                                   workers=args.workers)
    units = [unit_history(a, args.feature, exposure) for a in acts]
    attach_events(units, ev)
    eols = {k: v.failure for k, v in ev.items() if v.failure is not None}
    g, u, pl = _louo(units, eols, exposure, "mission", args.feature, args.samples, args.seed, True, name)
    return {"exposure": exposure, "life": g, "ukf": u, "plugin": pl, "reference": [],
            "reference_name": "- (no wear truth in these bags)"}


def csv_dataset(name, hi, events, args, level=None):
    from hd_prognostic.lifemodel import attach_events, read_events, read_hi_csv

    units = read_hi_csv(hi)
    ev = read_events(events)
    attach_events(units, ev, str(events))
    eols = {k: v.failure for k, v in ev.items() if v.failure is not None}
    g, u, pl = _louo(units, eols, "csv exposure", "step", "hi", args.samples, args.seed, True, name, level)
    return {"exposure": "time column", "life": g, "ukf": u, "plugin": pl}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench prognostics", description=__doc__.split("\n")[0])
    ap.add_argument("--fleet", action="append", default=[], metavar="NAME=DIR", help="simulated fleet (repeatable)")
    ap.add_argument("--events-fleet", action="append", default=[], metavar="NAME=DIR",
                    help="fleet of bags with its own DIR/events.csv (e.g. the independent plant), repeatable")
    ap.add_argument("--dev", default=None, help="fleet NAME on which the degradation clock is chosen (ML)")
    ap.add_argument("--exposure", default=None, choices=("missions", "hours", "load"),
                    help="fix the clock instead of choosing it on --dev")
    ap.add_argument("--nasa", default=None, help="folder with B0005.csv ... (NASA cells)")
    ap.add_argument("--virkler", default=None, help="folder with the Virkler CSV files")
    ap.add_argument("--virkler-every", type=int, default=1, help="score every k-th specimen (all are used to fit)")
    ap.add_argument("--virkler-specimens", default=None,
                    help="comma-separated specimen names: score only these (of the every-k-th ones)")
    ap.add_argument("--out", default="runs/bench_prognostics")
    ap.add_argument("--feature", default="HF_MTW_IF")
    ap.add_argument("--samples", type=int, default=1000)
    ap.add_argument("--particles", type=int, default=1000, help="reference PF particles")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--draws", type=int, default=20, help="posterior parameter draws per life-model fit")
    ap.add_argument("--threshold", default="auto", choices=("auto", "latent", "observable"),
                    help="failure threshold on the latent state, on the observable HI, or chosen by maximum "
                         "likelihood in every fit (training units only)")
    ap.add_argument("--path", default="auto", choices=("auto", "power", "paris"),
                    help="latent path family: power law, crack-growth (Paris) shape, or chosen by AIC in every fit "
                         "(training units only)")
    ap.add_argument("--no-known-level", dest="known_level", action="store_false",
                    help="NASA / Virkler: fit the observable threshold's level instead of taking it from the failure "
                         "definition (80 %% of rated capacity, 49.8 mm)")
    ap.add_argument("--failure-at", default="auto", choices=("auto", "crossing", "interval"),
                    help="failure-time likelihood: auto (the default) follows each dataset's failure definition "
                         "(lifemodel.failure_at_rule: crossing where failure is the recorded HI reaching a known level "
                         "and the records run through it, NASA and Virkler; interval otherwise, the bag fleets), or "
                         "force crossing (the density of the recorded crossing time, the level fixed or fitted by "
                         "AIC) / interval (failed between the last record and the failure time)")
    ap.add_argument("--exposure-rate", default="mean", choices=("median", "mean"),
                    help="the prognosis's rate of a unit's future exposure per mission: mean (default) or median of "
                         "its record's per-step rates (src/hd_prognostic/README.md, 'Dev-fleet coverage diagnosis'; "
                         "CSV datasets with exposure = time are unchanged)")
    ap.add_argument("--exposure-spread", default="renewal+rate", choices=("none", "renewal", "renewal+rate"),
                    help="the future exposure's variability in the RUL: renewal+rate (default: the renewal spread and "
                         "the sampling uncertainty of the unit's mean rate), renewal (inverse-Gaussian passage time from "
                         "the unit's per-step increment variance) or none (single-rate extrapolation)")
    ap.add_argument("--noise", default="auto", choices=("constant", "level", "auto"),
                    help="HI noise model: one sigma (constant), sigma sqrt(1 + kappa^2 L^2) growing with the latent "
                         "level (level), or auto (the default): the lower AIC of both in every fit (training units "
                         "only), the level fit compared only when its optimum is regular (interior, identified: "
                         "src/hd_prognostic/README.md, 'A regularity guard for the level noise')")
    ap.add_argument("--scale-prior", default="uniform", choices=("uniform", "log"),
                    help="prior of the between-unit scales (rate, offset, threshold scatter) in the parameter draws: "
                         "uniform on the sd (default) or 1/sd (log; src/hd_prognostic/README.md, 'Over-coverage of a "
                         "small fleet')")
    ap.add_argument("--hi-gain", default="shared", choices=("shared", "unit", "auto"),
                    help="HI gain: one for all units (shared, the default), per unit c (1 + g_i) with "
                         "g_i ~ N(0, s_g^2) marginalised (unit; latent threshold only), or auto: the per-unit gain "
                         "kept by AIC in each fit (src/hd_prognostic/README.md, 'A per-unit HI gain')")
    ap.add_argument("--virkler-failure", default=None, choices=("auto", "crossing", "interval"),
                    help="Virkler only: override --failure-at (kept for older commands)")
    ap.add_argument("--inspect-every", type=int, default=0, metavar="K",
                    help="simulated fleets: add an overhaul inspection every K missions to the events file written "
                         "from fleet_truth.json (the shop's gauge emulated from the truth; scoring side only)")
    ap.add_argument("--inspect-quantity", default="lost_motion", choices=("lost_motion", "wear_depth"),
                    help="what the shop measures: the output's lost motion / backlash [rad] or the flank wear depth [m]")
    ap.add_argument("--inspect-noise", type=float, default=None, metavar="SD",
                    help="measurement sd in SI (default: 0.1 arcmin for lost_motion, 1 um for wear_depth)")
    ap.add_argument("--inspect-at-failure", action="store_true",
                    help="also measure it at the teardown of every failed unit (its failure mission)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=1,
                    help="processes for the leave-one-unit-out folds (same results as 1, in the same order)")
    ap.add_argument("--no-reference", action="store_true")
    args = ap.parse_args(argv)
    DRAWS[0] = args.draws
    THRESHOLD[0] = args.threshold
    PATH[0] = args.path
    FAILURE_AT[0] = args.failure_at
    RATE[0] = args.exposure_rate
    SPREAD[0] = args.exposure_spread
    NOISE[0] = args.noise
    GAIN[0] = args.hi_gain
    SCALE_PRIOR[0] = args.scale_prior
    JOBS[0] = args.jobs
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    results = {}
    fleets = dict(f.split("=", 1) for f in args.fleet)
    exposure = args.exposure
    order = ([args.dev] if args.dev in fleets else []) + [n for n in fleets if n != args.dev]
    if exposure is None and args.dev not in fleets and fleets:
        print("error: give --dev NAME (one of the --fleet names) or --exposure", file=sys.stderr)
        return 2
    for n in order:
        t0 = time.perf_counter()
        results[n], exposure = sim_fleet(n, fleets[n], out, exposure, args)
        results[n]["seconds"] = time.perf_counter() - t0
    for spec in args.events_fleet:
        n, d = spec.split("=", 1)
        t0 = time.perf_counter()
        results[n] = events_fleet(n, d, exposure or "load", args)
        results[n]["seconds"] = time.perf_counter() - t0
    if args.nasa:
        from hd_prognostic.realdata import RATED_AH, battery_records, run_battery

        t0 = time.perf_counter()
        hi, ev = battery_records(args.nasa, out, eol_frac=0.8)
        # failure defined on the measured capacity: its level (80 % of rated) is the failure definition
        results["nasa"] = csv_dataset("nasa", hi, ev, args, level=0.8 * RATED_AH if args.known_level else None)
        r = run_battery(args.nasa, eol_fracs=(0.8,), n_particles=args.particles, seed=args.seed)
        results["nasa"]["reference"] = [dict(u["metrics"], unit=k) for k, u in r["units"].items()]
        results["nasa"]["reference_name"] = "exponential-fade PF, leave-one-cell-out prior (realdata.run_battery)"
        results["nasa"]["seconds"] = time.perf_counter() - t0
    if args.virkler:
        from hd_prognostic.realdata import VIRKLER_LENGTHS_MM, run_virkler, virkler_records

        t0 = time.perf_counter()
        hi, ev = virkler_records(args.virkler, out)
        FAILURE_AT[0] = args.virkler_failure or args.failure_at
        res = csv_dataset_every("virkler", hi, ev, args,  # failure defined as the measured length reaching 49.8 mm
                                level=VIRKLER_LENGTHS_MM[-1] * 1e-3 if args.known_level else None)
        r = run_virkler(args.virkler, n_particles=args.particles, seed=args.seed)
        scored = {m["unit"] for m in res["life"]}  # the same specimens as the life model's rows
        res["reference"] = [dict(u["metrics"], unit=f"specimen{k}") for k, u in r["units"].items()
                            if f"specimen{k}" in scored]
        res["reference_name"] = "Paris-law PF, 2-fold over specimens (realdata.run_virkler), same specimens"
        res["seconds"] = time.perf_counter() - t0
        results["virkler"] = res
    table = {}
    for n, r in results.items():
        table[n] = {"life model": _row(r["life"]), "UKF on it": _row(r["ukf"]), "plug-in": _row(r.get("plugin", [])),
                    "threshold bound": float(np.mean(list(r["bound"].values()))) if r.get("bound") else None,
                    "reference": _row(r.get("reference", [])), "exposure": r.get("exposure"),
                    "reference_name": r.get("reference_name"), "seconds": r.get("seconds"),
                    "threshold": _thr(r["life"]),
                    # the coverage's uncertainty over the dataset's units (metrics.coverage_interval)
                    "coverage_interval": _cov_interval(r["life"])}
    (out / "bench_prognostics.json").write_text(json.dumps({"table": table, "results": results}, indent=1,
                                                           default=lambda o: float(o) if np.isscalar(o) else str(o)))
    print()
    print("| dataset | units scored | clock | threshold (folds) | life model: in-cone / P5-P95 cov / CRA / CRPS | UKF on it | "
          "plug-in point estimate (no parameter draws) | reference | reference model | "
          "in-cone bound (true wear, population threshold) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, t in table.items():
        f = lambda r: (f"{r['frac_in_cone_lambda_ge_0.5']:.2f} / {r['coverage_p5_p95']:.2f} / {r['cra']:.2f} / "
                       f"{r['crps_mean']:.3g}" if r["n"] else "-")
        print(f"| {n} | {t['life model']['n']} | {t['exposure']} | {t['threshold']} | {f(t['life model'])} | {f(t['UKF on it'])} | "
              f"{f(t['plug-in'])} | "
              f"{f(t['reference'])} | {t['reference_name'] or '-'} | "
              f"{'-' if t['threshold bound'] is None else format(t['threshold bound'], '.2f')} |")
    print("\nlife model P5-P95 coverage over units (95 % intervals; target 0.85-0.95): unit bootstrap / Wilson with one "
          "trial per unit")
    for n, t in table.items():
        ci = t["coverage_interval"]
        if ci.get("n_units"):
            print(f"  {n}: {ci['coverage']:.3f} (SE {ci['se']:.3f}; {ci['n_units']} units) bootstrap [{ci['boot'][0]:.3f}, "
                  f"{ci['boot'][1]:.3f}] {'consistent' if ci['consistent_boot'] else 'NOT consistent'} with the target; "
                  f"Wilson [{ci['wilson'][0]:.3f}, {ci['wilson'][1]:.3f}]")
    print(f"\nwrote {out}/bench_prognostics.json; {time.perf_counter() - t_all:.0f} s in all")
    return 0


def _cov_interval(rows):
    """Coverage of the life model's rows with its unit-level uncertainty (bootstrap and binomial by unit)."""
    from hd_prognostic.metrics import coverage_interval

    return coverage_interval([r.get("coverage_p5_p95", float("nan")) for r in rows])


def _thr(rows):
    """Which threshold the folds' fits chose, e.g. 'observable 3/3'."""
    ks = [r.get("threshold") for r in rows if r.get("threshold")]
    return ", ".join(f"{k} {ks.count(k)}/{len(ks)}" for k in dict.fromkeys(ks)) or "-"


def csv_dataset_every(name, hi, events, args, level=None):
    """csv_dataset, scoring every k-th unit (``--virkler-every``) while each fit uses all the others."""
    from hd_prognostic.lifemodel import attach_events, read_events, read_hi_csv

    units = read_hi_csv(hi)
    ev = read_events(events)
    attach_events(units, ev, str(events))
    eols = {k: v.failure for k, v in ev.items() if v.failure is not None}
    k = max(1, args.virkler_every)
    scored = {u.unit for u in units[::k]}
    if getattr(args, "virkler_specimens", None):  # a subset of those (slow fits: Paris path ~3 min per fold)
        scored &= set(args.virkler_specimens.split(","))
    keep = {u: t for u, t in eols.items() if u in scored}
    g, u, pl = _louo_subset(units, keep, args, name, level)
    return {"exposure": "time column", "life": g, "ukf": u, "plugin": pl, "scored_every": k}


def _louo_subset(units, eols, args, name, level=None):
    """Leave-one-unit-out scoring the units in ``eols`` only (each fit uses all the other units)."""
    from hd_prognostic.lifemodel import LifeModel, UnitEvents

    def fold(i):
        u = units[i]
        t0 = time.perf_counter()
        m = LifeModel.fit([v for j, v in enumerate(units) if j != i], exposure="csv exposure", feature="hi",
                          time_unit="step", n_draws=DRAWS[0], seed=args.seed,
                          threshold="observable" if FAILURE_AT[0] == "crossing" else THRESHOLD[0],
                          failure_level=level, path=PATH[0], failure_at=FAILURE_AT[0], exposure_rate=RATE[0],
                          exposure_spread=SPREAD[0], noise=NOISE[0], scale_prior=SCALE_PRIOR[0],
                          hi_gain=GAIN[0])
        test = _copy_unit(u)
        test.events = UnitEvents()
        sg, su, sp = _predict_all(m, test, eols[u.unit], args.samples, args.seed)
        sg["threshold"] = _label(m)
        sg.update(_noise_fields(m))
        print(f"  {name} {u.unit}: EOL {eols[u.unit]:g}, life model in-cone {sg['frac_in_cone_lambda_ge_0.5']:.2f} "
              f"cov {sg['coverage_p5_p95']:.2f} | UKF {su['frac_in_cone_lambda_ge_0.5']:.2f} / "
              f"{su['coverage_p5_p95']:.2f} | plug-in {sp['frac_in_cone_lambda_ge_0.5']:.2f} / "
              f"{sp['coverage_p5_p95']:.2f} (threshold {sg['threshold']}{_noise_txt(m)})  "
              f"[{time.perf_counter() - t0:.1f} s]",
              flush=True)
        return sg, su, sp

    res = _run_folds(fold, [i for i, u in enumerate(units) if u.unit in eols])
    return [r[0] for r in res], [r[1] for r in res], [r[2] for r in res]


if __name__ == "__main__":
    sys.exit(main())
