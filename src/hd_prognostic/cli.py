"""Sub-commands of the prognostic package.

``hdphm prognose BAG_DIR --out DIR [--obs-model JSON]``
    particle-filter RUL history of one actuator (JSON + CSV + plots).
``hdphm metrics RUL_HISTORY --truth EOL|BAG_DIR``
    score a RUL history (truth: EOL time, or a simulated actuator's bags).
``hdphm prognostic eval FLEET_DIR --out DIR``
    held-out per-actuator evaluation on a simulated fleet (+ UKF baseline).
``hdphm prognostic features FLEET_DIR --out DIR``
    monotonicity / separability study of the health features.
``hdphm prognostic fit-obs FLEET_DIR --out JSON``
    fit the observation model + Archard prior on a (training) fleet.
``hdphm prognostic fit FLEET_DIR|HI.csv --events EVENTS.csv --out MODEL.json``
    the life model from HI histories + failure/removal/inspection events (``prognose --model`` uses it).
``hdphm prognostic battery|virkler --data DIR --out DIR [--export DIR]``
    the older particle filters on real degradation data, or the data as HI CSV + events (``--export``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _write_history(out: Path, hist, stem: str = "rul_history") -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(hist.to_json(), indent=1))
    with open(out / f"{stem}.csv", "w") as f:
        f.write(f"t_{hist.time_unit},z,rul_p5,rul_p50,rul_p95,rul_mean," + ",".join(
            f"{n}_mean" for n in hist.state_names) + ",ess\n")
        j = {t: i for i, t in enumerate(hist.rul_t)}
        for i, t in enumerate(hist.t):
            r = j.get(t)
            vals = [hist.p5[r], hist.p50[r], hist.p95[r], hist.mean[r]] if r is not None else [""] * 4
            f.write(",".join(str(v) for v in [t, hist.z[i], *vals, *hist.state_mean[i], hist.ess[i]]) + "\n")


def _one_actuator(args):
    """The one actuator ``prognose`` reads from the folder ``args.bag_dir``: every bag in it, or with ``--unit`` the
    unit's among several (a flat folder of a fleet, by metadata ``actuator_id``; a fleet of actuator folders, by
    folder name)."""
    from hd_prognostic.pipeline import extract_actuator, find_actuator_groups

    if not args.unit:  # one actuator's folder: every bag in it (the reader refuses another actuator's, by name)
        return extract_actuator(args.bag_dir, include_truth=False, progress=True)
    groups = find_actuator_groups(args.bag_dir)
    names = [n for n, _ in groups]
    groups = [g for g in groups if g[0] == args.unit]
    if not groups:
        raise ValueError(f"{args.bag_dir}: no actuator {args.unit!r} (it holds {', '.join(names[:8])}"
                         f"{', ...' if len(names) > 8 else ''})")
    return extract_actuator(args.bag_dir, include_truth=False, progress=True, bags=groups[0][1])


def _prognose(args) -> int:
    if args.model:
        return _prognose_life(args)
    from hd_prognostic.pipeline import DEFAULT_OBS_MODEL, build_model, prognose
    from hd_prognostic.observation import ObservationModel
    from hd_prognostic.plots import save_snapshot, save_state_history

    obs_path = Path(args.obs_model) if args.obs_model else DEFAULT_OBS_MODEL
    if not obs_path.exists():
        print(f"error: {obs_path}: observation model not found; fit one with "
              f"'hdphm prognostic fit-obs FLEET_DIR --out obs.json' and pass --obs-model", file=sys.stderr)
        return 2
    obs = ObservationModel.from_json(obs_path)
    out = Path(args.out)
    a = _one_actuator(args)
    n = len(a.mission_index)
    hist = prognose(a, obs, n_particles=args.particles, seed=args.seed, likelihood=args.likelihood,
                    snapshots=() if args.no_plots else (max(0, n // 2), max(0, n - 1)), progress=True)
    _write_history(out, hist)
    for s in hist.meta.get("notes", []):
        print(f"note: {s}", file=sys.stderr)
    if args.no_plots:
        print(f"{a.actuator_id}: wrote {out}/rul_history.json and .csv")
        return 0
    model = build_model(obs)
    for s in hist.meta.get("snapshots", []):
        save_snapshot(out / f"pf_mission{int(s['t'])}.png", s, model, model.h_fail,
                      title=f"{a.actuator_id}, mission {int(s['t'])}", state_scale=1e6, state_unit="um",
                      time_unit="mission")
    save_state_history(out / "state_history.png", hist, state_scale=1e6, state_unit="um",
                       title=f"{a.actuator_id}: wear estimate")
    last = hist.p5[-1], hist.p50[-1], hist.p95[-1]
    print(f"{a.actuator_id}: {n} missions, last RUL P5/P50/P95 = {last[0]:.0f}/{last[1]:.0f}/{last[2]:.0f} missions; "
          f"wrote {out}/rul_history.json, .csv and plots")
    if a.errors:
        print(f"{len(a.errors)} notes about the bags (skipped or reordered; in rul_history.json meta)", file=sys.stderr)
    return 0


def _metrics(args) -> int:
    import numpy as np

    from hd_prognostic import metrics as M
    from hd_prognostic.plots import save_alpha_lambda
    from hd_prognostic.tracking import RULHistory

    p = Path(args.rul_history)
    try:
        hist = RULHistory.from_json(json.loads(p.read_text()))
    except (OSError, json.JSONDecodeError, KeyError) as e:
        print(f"error: {p}: not a RUL history ({e})", file=sys.stderr)
        return 2
    try:
        eol = float(args.truth)
    except ValueError:
        from hd_prognostic.pipeline import extract_actuator

        a = extract_actuator(args.truth, include_truth=True)
        eol = a.eol_mission()
        if not np.isfinite(eol):
            print(f"error: {args.truth}: wear never reaches h_fail: no end of life to score against", file=sys.stderr)
            return 2
    m = M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, eol, alpha=args.alpha,
                        samples=hist.samples or None,  # quantile grid from the history: PIT and CRPS
                        weights=hist.sample_weights or None, rul_horizon=hist.meta.get("rul_horizon"))
    out = Path(args.out) if args.out else p.parent
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(m, indent=2, default=float))
    save_alpha_lambda(out / "alpha_lambda.png", hist.rul_t, hist.p50, hist.p5, hist.p95, eol, args.alpha,
                      title=f"{hist.unit}: alpha-lambda (alpha = {args.alpha:g})", unit=hist.time_unit)
    print(json.dumps({k: v for k, v in m.items() if k != "pit"}, indent=2, default=float))
    return 0


def _eval(args) -> int:
    from hd_prognostic.evaluate import fleet_eval, load_fleet
    from hd_prognostic.pipeline import JOINT

    out = Path(args.out)
    fleet = load_fleet(args.fleet_dir, cache_dir=out / "cache", workers=args.workers)
    s = fleet_eval(fleet, out, folds=args.folds, n_particles=args.particles, seed=args.seed, feature=args.feature,
                   degree=args.degree, likelihood=args.likelihood, with_ukf=not args.no_ukf,
                   fuse=args.fuse.split(",") if args.fuse else None,
                   **(JOINT if args.joint else {"baseline": args.baseline}))
    ag = s["aggregate"]
    print("PF aggregate:", json.dumps(ag, indent=1, default=float))
    if s["ukf_aggregate"]:
        print("UKF aggregate:", json.dumps(s["ukf_aggregate"], indent=1, default=float))
    if s["censored"]:
        print("not scored (no end of life):", s["censored"])
    print(f"wrote {out}/eval_summary.json, eval_per_actuator.csv, alpha_lambda.png")
    return 0


def _features(args) -> int:
    from hd_prognostic.evaluate import feature_study, load_fleet

    out = Path(args.out)
    import numpy as np

    fleet = load_fleet(args.fleet_dir, cache_dir=out / "cache", workers=args.workers)
    # The study ranks features against the true wear (/sim/health): recorded bags have none, and
    # every score would be NaN. Refuse clearly instead of printing a table of NaN.
    with_truth = [a for a in fleet if a.h_true is not None and np.isfinite(a.h_true).sum() >= 2]
    if not with_truth:
        raise ValueError(f"{args.fleet_dir}: no actuator has wear ground truth (/sim/health) in its bags; the "
                         "feature study scores features against the true wear, so it needs a simulated fleet "
                         "(recorded bags: use 'hdphm prognose BAG_DIR')")
    if len(with_truth) < len(fleet):
        print(f"note: {len(fleet) - len(with_truth)} of {len(fleet)} actuators have no wear truth and are left "
              "out of the study", file=sys.stderr)
    res = feature_study(with_truth, out)
    for f, r in res.items():
        print(f"{f:20s} Spearman {r['spearman_mean']:+.2f} (min {r['spearman_min']:+.2f})  "
              f"Coble {r['coble_monotonicity_mean']:.2f}  AUC {r['auc_early_vs_advanced']:.2f}  "
              f"Fisher {r['fisher_ratio']:.1f}")
    print(f"wrote {out}/feature_monotonicity.png, feature_separability.png, hf_vs_wear.png, fault_to_failure.png")
    return 0


def _fit_obs(args) -> int:
    from hd_prognostic.evaluate import load_fleet
    from hd_prognostic.pipeline import JOINT, fit_population

    fleet = load_fleet(args.fleet_dir, cache_dir=args.cache, workers=args.workers)
    kw = {k: v for k, v in JOINT.items() if k != "pf_options"} if args.joint else {"baseline": args.baseline}
    obs = fit_population(fleet, feature=args.feature, degree=args.degree,
                         fuse=args.fuse.split(",") if args.fuse else None, **kw)
    obs.to_json(args.out)
    print(json.dumps({"fit_info": obs.fit_info, "degradation": obs.degradation}, indent=1))
    print(f"wrote {args.out}")
    return 0


def _battery(args) -> int:
    import numpy as np

    from hd_prognostic.plots import save_alpha_lambda_grid, save_state_history
    from hd_prognostic.realdata import run_battery

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.export:
        from hd_prognostic.realdata import battery_records

        hi, ev = battery_records(args.data, args.export, eol_frac=args.eol_frac)
        print(f"wrote {hi} and {ev}: run 'hdphm prognostic fit {hi} --events {ev} --out MODEL.json'")
        return 0
    r = run_battery(args.data, n_particles=args.particles, seed=args.seed, t_start=args.t_start,
                    regen_nu=args.regen_nu)
    hists = [u["history"] for u in r["units"].values()]
    eols = [h.meta["t_eol"] for h in hists]
    save_alpha_lambda_grid(out / "battery_alpha_lambda.png", hists, eols, 0.2, unit="cycle",
                           title="NASA cells, exponential-fade PF (leave-one-cell-out prior)")
    for h in hists:
        save_state_history(out / f"battery_state_{h.unit.replace('%', 'pct').replace('@', '_')}.png", h,
                           title=h.unit, state_unit="Ah")
        _write_history(out, h, f"battery_{h.unit.replace('%', 'pct').replace('@', '_')}")
    summ = {"per_unit": {k: {kk: vv for kk, vv in u["metrics"].items() if kk != "pit"} for k, u in r["units"].items()},
            "aggregate": r["aggregate"], "skipped": r["skipped"]}
    (out / "battery_metrics.json").write_text(json.dumps(summ, indent=2, default=float))
    for k, u in r["units"].items():
        m = u["metrics"]
        print(f"{k}: EOL cycle {m['t_eol']:.0f}, in-cone(lambda>=0.5) {m['frac_in_cone_lambda_ge_0.5']:.2f}, "
              f"P5-P95 coverage {m['coverage_p5_p95']:.2f}, RA(0.5) {m['relative_accuracy_lambda_0.5']:.2f}, "
              f"CRA {m['cra']:.2f}, CRPS {m.get('crps_mean', np.nan):.1f} cycles")
        for tp in (40, 60, 80, 100):
            h = u["history"]
            if tp in h.rul_t and tp < m["t_eol"]:
                i = h.rul_t.index(tp)
                print(f"    predicted at cycle {tp}: RUL P50 {h.p50[i]:.0f} [P5 {h.p5[i]:.0f}, P95 {h.p95[i]:.0f}]"
                      f" vs true {m['t_eol'] - tp:.0f}")
    print(f"skipped: {r['skipped']}")
    print(f"wrote {out}/battery_metrics.json, battery_alpha_lambda.png")
    return 0


def _virkler(args) -> int:
    from hd_prognostic.plots import save_alpha_lambda_grid
    from hd_prognostic.realdata import run_virkler

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.export:
        from hd_prognostic.realdata import virkler_records

        hi, ev = virkler_records(args.data, args.export)
        print(f"wrote {hi} and {ev}: run 'hdphm prognostic fit {hi} --events {ev} --out MODEL.json'")
        return 0
    r = run_virkler(args.data, n_particles=args.particles, seed=args.seed, max_specimens=args.max_specimens)
    hs = [u["history"] for u in r["units"].values()]
    sel = hs[:: max(1, len(hs) // 9)][:9]
    save_alpha_lambda_grid(out / "virkler_alpha_lambda.png", sel, [h.meta["t_eol"] for h in sel], 0.2,
                           unit="cycle", title="Virkler specimens (held-out half), Paris-law PF")
    summ = {"fits": r["fits"], "aggregate": r["aggregate"],
            "per_specimen": {str(k): {kk: vv for kk, vv in u["metrics"].items() if kk != "pit"}
                             for k, u in r["units"].items()}}
    (out / "virkler_metrics.json").write_text(json.dumps(summ, indent=2, default=float))
    print("Paris fits (2 folds):", json.dumps(r["fits"], default=float))
    print("aggregate over held-out specimens:", json.dumps(r["aggregate"], indent=1, default=float))
    print(f"wrote {out}/virkler_metrics.json, virkler_alpha_lambda.png")
    return 0


def _life_sources(src: str, events: str | None, feature: str, exposure: str, cache=None, workers: int = 1,
                  progress: bool = False):
    """SOURCE (fleet folder of actuator folders, or a ``unit,time,hi[,exposure]`` CSV) + events ->
    ({exposure name: [UnitHistory]}, feature name, time unit, notes, gear ratios of the bags or None). Contract
    topics only."""
    from hd_prognostic.lifemodel import EXPOSURES, attach_events, read_events, read_hi_csv

    ev = read_events(events) if events else {}
    p = Path(src)
    notes = []
    if p.is_file():
        units = read_hi_csv(p)
        notes += attach_events(units, ev, str(events))
        name = "csv exposure" if exposure in ("auto", "csv") else exposure
        return {name: units}, "hi", "step", notes, None
    from hd_prognostic.pipeline import gear_ratios, load_fleet_histories, unit_history

    names = list(EXPOSURES) if exposure == "auto" else [exposure]
    acts, _ = load_fleet_histories(p, feature, "missions", cache_dir=cache, workers=workers, progress=progress)
    out = {}
    for n in names:
        try:
            units = [unit_history(a, feature, n) for a in acts]
        except ValueError as e:
            if exposure != "auto":
                raise
            notes.append(f"exposure {n}: {e}")
            continue
        notes += attach_events(units, ev, str(events))
        out[n] = units
    Ns = gear_ratios(acts)
    if len(Ns) > 1:
        notes.append(f"{p}: the fleet mixes gear ratios {', '.join(f'{v:g}' for v in Ns)}: one life model is fitted "
                     "to all of them (the health indicator's scale may differ by transmission type)")
    return out, feature, "mission", notes, Ns


def _fit_life(args) -> int:
    from hd_prognostic.lifemodel import fit_best

    cands, feature, tu, notes, Ns = _life_sources(args.source, args.events, args.feature, args.exposure,
                                                  cache=args.cache, workers=args.workers, progress=True)
    for n in dict.fromkeys(notes):
        print(f"note: {n}", file=sys.stderr)
    m = fit_best(cands, feature=feature, time_unit=tu, progress=True, n_draws=args.draws, threshold=args.threshold,
                 failure_level=args.failure_level, path=args.path, failure_at=args.failure_at, noise=args.noise,
                 exposure_spread=args.exposure_spread, hi_gain=args.hi_gain)
    if Ns:
        m.fit_info["gear_ratio"] = Ns  # transmission types the fit has seen (prognose notes another)
    m.to_json(args.out)
    fi = m.fit_info
    print(json.dumps({"exposure": m.exposure, "E_ref": m.E_ref, **m.to_json()["readable"],
                      "inspections": m.inspections, "log_likelihood": fi["log_likelihood"],
                      "units": fi["n_units"], "failures": fi["n_failures"], "censored": fi["n_censored"],
                      "exposure_candidates": fi.get("exposure_candidates"),
                      "threshold_candidates": fi.get("threshold_candidates"),
                      "path": m.path, "path_aic": fi.get("path_aic"),
                      "failure_at": fi.get("failure_at", "interval"), "failure_at_rule": fi.get("failure_at_rule"),
                      "level": fi.get("level"),
                      "level_aic": fi.get("level_aic"),
                      "noise": fi.get("noise", "constant"), "noise_aic": fi.get("noise_aic"),
                      "noise_rule": fi.get("noise_rule"),
                      "hi_gain": fi.get("hi_gain", "shared"), "gain_aic": fi.get("gain_aic"),
                      "parameter_draws": len(m.draws),
                      "parameter_draws_ess": fi.get("parameter_uncertainty", {}).get("ess")}, indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


def _prognose_life(args) -> int:
    from hd_prognostic.lifemodel import LifeModel, attach_events, predict_history, read_events, read_hi_csv
    from hd_prognostic.plots import save_state_history

    model = LifeModel.from_json(args.model)
    out = Path(args.out)
    src = Path(args.bag_dir)
    ev = read_events(args.events) if args.events else {}
    if src.is_file():
        units = read_hi_csv(src)
        if args.unit:
            units = [u for u in units if u.unit == args.unit]
            if not units:
                raise ValueError(f"{src}: no unit {args.unit!r}")
        elif len(units) != 1:
            raise ValueError(f"{src}: {len(units)} units in the file; choose one with --unit")
        u = units[0]
    else:
        from hd_prognostic.pipeline import other_transmission, unit_history

        if model.exposure not in ("missions", "hours", "load"):
            raise ValueError(f"{args.model}: fitted on CSV exposure ({model.exposure}); give a CSV file")
        a = _one_actuator(args)
        u = unit_history(a, model.feature, model.exposure)
        Ns_fit = model.fit_info.get("gear_ratio")
        Ns_own = other_transmission(a, Ns_fit)
        if Ns_own:
            msg = (f"{a.actuator_id}: gear ratio {', '.join(f'{v:g}' for v in Ns_own)}, the life model was fitted on "
                   f"{', '.join(f'{v:g}' for v in Ns_fit)}: another transmission type, whose health indicator may "
                   "scale differently")
            u.notes.append(msg)
            print(f"note: {msg}", file=sys.stderr)
    notes = attach_events([u], {k: v for k, v in ev.items() if k == u.unit}, str(args.events))
    if u.events.failure is not None:  # prognosis of a failed unit: its record before the failure only
        notes.append(f"{u.unit}: failure at {u.events.failure:g} in the events; RUL shown up to it")
    u.events.failure = u.events.removal = None
    hist = predict_history(model, u, n_samples=args.samples, seed=args.seed,
                           method="ukf" if args.ukf else "grid")
    hist.meta["notes"] = notes + u.notes
    _write_history(out, hist)
    for s in notes:
        print(f"note: {s}", file=sys.stderr)
    if not args.no_plots:
        save_state_history(out / "state_history.png", hist, state_scale=1.0, state_unit="x median threshold",
                           title=f"{u.unit}: latent degradation (1 = median failure threshold)")
    rh = hist.meta.get("rul_hours")
    extra = (f" = {rh['p50'][-1]:.0f} h [{rh['p5'][-1]:.0f}, {rh['p95'][-1]:.0f}]" if rh else "")
    print(f"{u.unit}: {len(u.t)} records, last RUL P5/P50/P95 = {hist.p5[-1]:.1f}/{hist.p50[-1]:.1f}/"
          f"{hist.p95[-1]:.1f} {model.time_unit}s{extra}; wrote {out}/rul_history.json and .csv")
    return 0


def _guard(fn):
    """Bad input (missing folder, unusable bags, bad JSON) -> one clear error line and exit status 2."""
    def run(args):
        try:
            return fn(args)
        except (FileNotFoundError, ValueError, KeyError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
    run.__name__ = fn.__name__
    return run


def _add_population_args(p) -> None:
    """Options of the observation-model / prior fit, shared by ``prognostic eval`` and ``fit-obs``."""
    p.add_argument("--feature", default="HF_MTW_IF")
    p.add_argument("--degree", type=int, default=2)
    p.add_argument("--workers", type=int, default=1, help="processes for reading the bags")
    p.add_argument("--baseline", choices=("subtract", "ratio", "none", "state"), default="subtract",
                   help="per-unit feature offset: median of the first missions subtracted (default) or "
                        "estimated jointly with the wear (state)")
    p.add_argument("--joint", action="store_true",
                   help="joint estimator: offset state, Liu-West kernel, h = kappa U, predictive kappa prior "
                        "(better wear tracking; RUL accuracy not better, see the README)")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("prognose", help="RUL history of one actuator's bags (or one unit of a HI CSV)")
    p.add_argument("bag_dir", help="folder with one actuator's mission bags (*.mcap), or a unit,time,hi CSV")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--model", default=None,
                   help="life model from 'hdphm prognostic fit' (failures/removals/inspections); without it the "
                        "older wear-truth-calibrated particle filter runs (--obs-model)")
    p.add_argument("--events", default=None, help="events CSV: this unit's inspections are used (life model)")
    p.add_argument("--unit", default=None, help="unit of a multi-unit CSV, or actuator of a folder holding several "
                                                "(a flat fleet folder: by metadata actuator_id; actuator folders: by name)")
    p.add_argument("--samples", type=int, default=2000, help="RUL samples per prediction (life model)")
    p.add_argument("--ukf", action="store_true", help="life model: UKF posterior instead of the exact grid")
    p.add_argument("--obs-model", default=None, help="observation-model JSON (default: the packaged one)")
    p.add_argument("--particles", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--likelihood", choices=("gaussian", "student_t"), default="student_t")
    p.add_argument("--no-plots", action="store_true", help="write the history only")
    p.set_defaults(func=_guard(_prognose))

    p = sub.add_parser("metrics", help="score a RUL history against the true end of life")
    p.add_argument("rul_history", help="rul_history.json from 'hdphm prognose'")
    p.add_argument("--truth", required=True, help="true EOL (same time unit) or the simulated actuator's bag folder")
    p.add_argument("--alpha", type=float, default=0.2)
    p.add_argument("--out", default=None, help="output folder (default: next to the history)")
    p.set_defaults(func=_guard(_metrics))

    pg = sub.add_parser("prognostic", help="prognostic evaluations: eval, features, fit-obs, battery, virkler")
    s = pg.add_subparsers(dest="prognostic_cmd", metavar="SUBCOMMAND")
    p = s.add_parser("eval", help="held-out per-actuator evaluation on a simulated fleet")
    p.add_argument("fleet_dir")
    p.add_argument("--out", default="runs/prognostic_eval")
    p.add_argument("--folds", type=int, default=4)
    p.add_argument("--particles", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    _add_population_args(p)
    p.add_argument("--likelihood", choices=("gaussian", "student_t"), default="student_t")
    p.add_argument("--no-ukf", action="store_true", help="skip the UKF baseline")
    p.add_argument("--fuse", default=None, metavar="F1,F2,...",
                   help="fuse these features into one health index (wear regression on the training actuators)")
    p.set_defaults(func=_guard(_eval))
    p = s.add_parser("fit", help="fit the life model from HI histories + failure/removal/inspection events")
    p.add_argument("source", help="fleet folder (one folder of bags per actuator) or a unit,time,hi[,exposure] CSV")
    p.add_argument("--events", required=True, help="CSV actuator_id,mission_index,event,quantity,value")
    p.add_argument("--out", required=True, help="model JSON to write")
    p.add_argument("--feature", default="HF_MTW_IF", help="health indicator (onboard per-mission feature)")
    p.add_argument("--exposure", choices=("auto", "missions", "hours", "load"), default="auto",
                   help="degradation clock; auto: the maximum-likelihood one (bags only)")
    p.add_argument("--cache", default=None, help="per-actuator feature cache folder")
    p.add_argument("--workers", type=int, default=1, help="processes for reading the bags")
    p.add_argument("--draws", type=int, default=20,
                   help="posterior draws of the population parameters mixed by the prognosis (0: point estimate)")
    p.add_argument("--threshold", choices=("auto", "latent", "observable"), default="auto",
                   help="failure threshold on the latent degradation or on the measured HI; auto: the "
                        "maximum-likelihood one (same parameter count, so also the AIC choice)")
    p.add_argument("--path", choices=("power", "paris", "auto"), default="auto",
                   help="latent path family: power law, crack-growth (Paris-type, accelerating to a finite-time "
                        "blow-up) shape, or auto (the default, the README's and the bench's model): both fitted, the "
                        "lower AIC kept (a fit costs a few times the power law's; --path power for the quick one)")
    p.add_argument("--failure-level", type=float, default=None, metavar="HI",
                   help="when failure is defined as the measured HI reaching a known level (e.g. 1.6 Ah, 0.0498 m): "
                        "that level, the observable threshold's median (not fitted then; with --failure-at "
                        "crossing: this level or one fitted in the path's coordinates, the lower AIC)")
    p.add_argument("--failure-at", choices=("auto", "interval", "crossing"), default="auto",
                   help="interval: a failure at t_f happened between the last record and t_f (found failed); "
                        "crossing: t_f is the time the measured HI reached the failure level (e.g. Virkler's cycles "
                        "at 49.8 mm, NASA's first cycle at <= 1.6 Ah): its density is scored (observable threshold "
                        "only); auto (the default): crossing when --failure-level is given and every failed unit's "
                        "records run through its failure, the record at the failure time being the first at or past "
                        "the level, else interval (the failure definition decides, not a score; printed as "
                        "failure_at_rule)")
    p.add_argument("--noise", choices=("constant", "level", "auto"), default="auto",
                   help="HI noise model: one sigma (constant), sigma sqrt(1 + kappa^2 L^2) growing with the latent "
                        "level L (level), or auto (the default, the bench's): the level-dependent noise fitted for the "
                        "path and threshold the constant noise chose, the lower AIC kept, compared only when its "
                        "optimum is regular (interior, identified; printed as noise_rule; src/hd_prognostic/README.md)")
    p.add_argument("--hi-gain", choices=("shared", "unit", "auto"), default="shared",
                   help="HI gain: one for all units (shared, the default), per unit c (1 + g_i), g_i ~ N(0, s_g^2), "
                        "marginalised with the offset (unit; latent threshold), or auto: the per-unit gain fitted "
                        "from the chosen fit's optimum and kept by AIC (identifiable from a unit's inspections; "
                        "src/hd_prognostic/README.md, 'A per-unit HI gain')")
    p.add_argument("--exposure-spread", choices=("none", "renewal", "renewal+rate"), default="renewal+rate",
                   help="the future exposure's variability in the prognosis: renewal+rate (the default, the bench's: "
                        "the renewal spread of the unit's per-step increments and its mean rate's sampling "
                        "uncertainty), renewal, or none")
    p.set_defaults(func=_guard(_fit_life))
    p = s.add_parser("features", help="monotonicity/separability of the health features on a simulated fleet")
    p.add_argument("fleet_dir")
    p.add_argument("--out", default="runs/prognostic_features")
    p.add_argument("--workers", type=int, default=1, help="processes for reading the bags")
    p.set_defaults(func=_guard(_features))
    p = s.add_parser("fit-obs", help="fit the observation model + Archard prior on a training fleet")
    p.add_argument("fleet_dir")
    p.add_argument("--out", required=True, help="JSON to write")
    _add_population_args(p)
    p.add_argument("--cache", default="runs/prognostic_cache", help="per-actuator feature cache folder")
    p.add_argument("--fuse", default=None, metavar="F1,F2,...",
                   help="fuse these features into one health index (wear regression on the training actuators)")
    p.set_defaults(func=_guard(_fit_obs))
    p = s.add_parser("battery", help="NASA B0005-7: exponential-fade PF (leave-one-cell-out), or --export the "
                                      "cells as HI CSV + events for 'prognostic fit'")
    p.add_argument("--data", required=True, help="folder with B0005.csv ... (columns cycle,capacity_ah), e.g. "
                                                 "data/measured/nasa_battery of the shared data")
    p.add_argument("--export", default=None, metavar="DIR", help="write battery_hi.csv + battery_events.csv")
    p.add_argument("--eol-frac", type=float, default=0.8, help="failure capacity / rated 2 Ah (--export)")
    p.add_argument("--out", default="runs/prognostic_battery")
    p.add_argument("--particles", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--t-start", type=float, default=20.0, help="first prediction cycle")
    p.add_argument("--regen-nu", type=float, default=0.0,
                   help="dof of the upper (capacity-regeneration) likelihood tail; 0 = symmetric Student-t")
    p.set_defaults(func=_guard(_battery))
    p = s.add_parser("virkler", help="Virkler crack growth: Paris-law PF (2-fold over specimens), or --export "
                                      "the specimens as HI CSV + events for 'prognostic fit'")
    p.add_argument("--data", required=True, help="folder with VirklerData-Raw.csv and VirklerData.csv")
    p.add_argument("--export", default=None, metavar="DIR", help="write virkler_hi.csv + virkler_events.csv")
    p.add_argument("--out", default="runs/prognostic_virkler")
    p.add_argument("--particles", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-specimens", type=int, default=None, help="held-out specimens per fold (default: all)")
    p.set_defaults(func=_guard(_virkler))
    pg.set_defaults(func=lambda a: (pg.print_help(), 2)[1])
