"""``hdphm demo``: the README's main job, end to end.

1. simulate a small fleet of actuators from new to failure (``hd_sim``);
2. train a ``small`` physics-informed twin on the training actuators and export it to ONNX (``hd_twin``);
3. write the training actuators' failures as an operator's events file (``events_train.csv``: the mission each
   was found failed at) and fit the prognostic life model on their contract bags and those events alone
   (``hd_prognostic.lifemodel``, what ``hdphm prognostic fit`` does; no wear truth);
4. replay the held-out actuator's whole life through the ROS 2 stack (twin core, onboard, prognostic,
   ground nodes) and record everything to MCAP;
5. print fault flags, health and RUL, and score the RUL against the simulator's truth.

The held-out actuator is never used to fit anything; its ground truth
(``fleet_truth.json``) is read only in step 5, to score.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path


def _say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def _simulate(out: Path, args) -> dict:
    from hd_sim import simulate_fleet

    truth_path = out / "fleet_truth.json"
    if truth_path.exists() and not args.fresh:
        _say(f"1/5 fleet already in {out} (use --fresh to re-simulate)")
        return json.loads(truth_path.read_text())
    _say(f"1/5 simulating {args.actuators} actuators, new to failure, {args.duration:g} s inspection missions")
    return simulate_fleet(args.actuators, args.max_missions, out, seed=args.seed, duration=args.duration,
                          workers=args.workers, overrides={"mission_hours": args.mission_hours},
                          sim_internal_every=0, progress=True)


def _bags_of(fleet: Path, aid: str) -> list[Path]:
    return sorted((fleet / aid).glob("*.mcap"))


def _train(fleet: Path, train_ids: list[str], out: Path, args) -> dict:
    from hd_twin.train import TrainConfig, load_missions, train_twin

    if (out / "config.json").exists() and (out / "model.onnx").exists() and not args.fresh:
        _say(f"2/5 twin already in {out}")
        return json.loads((out / "metrics.json").read_text()) if (out / "metrics.json").exists() else {}
    bags = []
    for aid in train_ids:
        b = _bags_of(fleet, aid)
        step = max(1, len(b) // args.twin_bags_per_actuator)
        bags += b[::step]
    _say(f"2/5 training the 'small' twin on {len(bags)} missions of {len(train_ids)} training actuators "
         f"(validation on held-out actuators inside that set)")
    cfg = TrainConfig.from_preset("small", seed=args.seed, epochs=args.epochs)
    res = train_twin(load_missions(bags), out, cfg)
    v = res.metrics["validation"]
    _say(f"    twin: validation NRMSE {v['nrmse_pct']:.2f} %, R^2 {v['r2']:.4f}, "
         f"{res.metrics['train_time_s']:.0f} s training")
    return res.metrics


def _fit_life(fleet: Path, train_ids: list[str], truth: dict, out_json: Path, args):
    """The operator's records of the training actuators (failure missions) -> events file -> life model."""
    from hd_prognostic.pipeline import extract_actuator, unit_history
    from hd_prognostic.lifemodel import EXPOSURES, UnitEvents, attach_events, fit_best, read_events, write_events

    ev_path = out_json.parent / "events_train.csv"
    write_events(ev_path, {a["actuator_id"]: UnitEvents(failure=float(a["eol_mission"])) for a in truth["actuators"]
                           if a["actuator_id"] in train_ids and a.get("eol_mission") is not None})
    _say(f"3/5 fitting the life model on {len(train_ids)} training actuators' contract bags and their failures "
         f"({ev_path.name}; no wear truth)")
    acts = [extract_actuator(fleet / aid, include_truth=False, cache=out_json.parent / f"features_{aid}.json")
            for aid in train_ids]
    ev = read_events(ev_path)
    cands = {}
    for e in EXPOSURES:
        units = [unit_history(a, "HF_MTW_IF", e) for a in acts]
        attach_events(units, ev, str(ev_path))
        cands[e] = units
    # the future exposure's spread and the HI noise as `hdphm prognostic fit` has them by default (renewal + the mean
    # rate's uncertainty; the level-dependent noise kept by AIC only at a regular optimum)
    m = fit_best(cands, feature="HF_MTW_IF", exposure_spread="renewal+rate", noise="auto")
    m.to_json(out_json)
    _say(f"    life model: clock '{m.exposure}' (maximum likelihood), {m.fit_info['n_failures']} failures, "
         f"HI noise {m.fit_info.get('noise', 'constant')}")
    return m


def _replay(bags: list[Path], model_dir: Path, life_json: Path, out_dir: Path, domain_id: int | None = None) -> dict:
    from hdphm.stack import run_stack_on_bags

    _say(f"4/5 replaying {len(bags)} missions of the held-out actuator through the ROS 2 stack, "
         f"recording one MCAP per mission under {out_dir}")
    return run_stack_on_bags([str(b) for b in bags], model_dir=str(model_dir), out_mcap=str(out_dir), rate="max",
                             overrides={"prognostic": {"life_model": str(life_json)}}, split_per_mission=True,
                             domain_id=domain_id)


def _own_actuator(summary: dict, aid: str) -> None:
    """Keep the held-out actuator's flags and counts; name any other actuator the nodes heard.

    The stack runs on a ROS domain (``--domain-id``, default ``$ROS_DOMAIN_ID`` or 0) that another ROS 2
    graph on this host or network may share; the nodes then (correctly) process its messages too. The
    demo's figures are about the replayed actuator, so foreign traffic is reported, not counted."""
    flags = summary.get("flags") or []
    foreign = sorted({str(f.get("actuator")) for f in flags if f.get("actuator") != aid}
                     | {str(a) for a in (summary.get("health") or {}) if a != aid})
    summary["flags"] = [f for f in flags if f.get("actuator") == aid]
    summary["n_warn"] = sum(1 for f in summary["flags"] if f["level"] == 1)
    summary["n_error"] = sum(1 for f in summary["flags"] if f["level"] == 2)
    summary["foreign_actuators"] = foreign
    if foreign:
        dom = os.environ.get("ROS_DOMAIN_ID", "0")
        print(f"note: the nodes also received messages of actuators not in this replay ({', '.join(foreign)}): another "
              f"ROS 2 graph shares this ROS domain ({dom}); they are left out of the figures below. Run the demo "
              "with --domain-id N (or ROS_DOMAIN_ID) on a domain of its own.", file=sys.stderr)


def _score_node(summary: dict, aid: str, eol: int | None) -> dict:
    """Score the prognostic node's own per-mission RUL (what the stack published) against truth."""
    from hd_prognostic import metrics as M

    rows = [r for r in (summary.get("health_history") or {}).get(aid, []) if "rul_p50" in r]
    if not rows or eol is None:
        return {}
    t = [float(r["mission_index"]) for r in rows]
    return M.score_history(t, [r["rul_p50"] for r in rows], [r["rul_p5"] for r in rows],
                           [r["rul_p95"] for r in rows], float(eol), alpha=0.2)


def _score(fleet: Path, aid: str, life_json: Path, out: Path, truth: dict, args) -> dict:
    """Batch prognosis with the same model as the node, scored against the simulator's truth (scoring only)."""
    from hd_prognostic import metrics as M
    from hd_prognostic.pipeline import extract_actuator, unit_history
    from hd_prognostic.lifemodel import LifeModel, predict_history
    from hd_prognostic.plots import save_alpha_lambda

    model = LifeModel.from_json(life_json)
    a = extract_actuator(fleet / aid, include_truth=False)
    eol0 = next(x["eol_mission"] for x in truth["actuators"] if x["actuator_id"] == aid)
    u = unit_history(a, model.feature, model.exposure)
    if eol0 is not None:  # the bag of the mission it was found failed at is not flown: predict before it
        keep = u.t < eol0
        u.t, u.y, u.E = u.t[keep], u.y[keep], u.E[keep]
    hist = predict_history(model, u, seed=args.seed)
    (out / f"rul_history_{aid}.json").write_text(json.dumps(hist.to_json(), indent=1))
    eol = next(x["eol_mission"] for x in truth["actuators"] if x["actuator_id"] == aid)
    if eol is None:
        return {"note": f"{aid} did not reach end of life within {args.max_missions} missions: nothing to score"}
    m = M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, float(eol), alpha=0.2, samples=hist.samples,
                        rul_horizon=hist.meta.get("rul_horizon"))
    m.pop("pit", None)
    save_alpha_lambda(out / f"alpha_lambda_{aid}.png", hist.rul_t, hist.p50, hist.p5, hist.p95, float(eol), 0.2,
                      title=f"{aid}: RUL (held-out actuator)", unit="missions")
    m["eol_mission"] = eol
    m["last"] = {"t": hist.rul_t[-1], "p5": hist.p5[-1], "p50": hist.p50[-1], "p95": hist.p95[-1]}
    return m


def run_demo(args) -> int:
    t_start = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fleet = out / "fleet"
    truth = _simulate(fleet, args)
    ids = sorted(a["actuator_id"] for a in truth["actuators"])
    if len(ids) < 3:
        print("error: the demo needs >= 3 actuators (training ones + one held out)", file=sys.stderr)
        return 2
    test_id, train_ids = ids[-1], ids[:-1]
    twin_metrics = _train(fleet, train_ids, out / "twin", args)
    life_json = out / "life_model.json"
    _fit_life(fleet, train_ids, truth, life_json, args)
    bags = _bags_of(fleet, test_id)
    summary = _replay(bags, out / "twin", life_json, out / f"stack_{test_id}", args.domain_id)
    _own_actuator(summary, test_id)
    _say("5/5 scoring the RUL of the held-out actuator against the simulator's truth (evaluation only)")
    score = _score(fleet, test_id, life_json, out, truth, args)
    score["node"] = _score_node(summary, test_id, score.get("eol_mission"))

    report = {"held_out_actuator": test_id, "training_actuators": train_ids, "twin": twin_metrics.get("validation"),
              "stack": {k: summary.get(k) for k in ("n_warn", "n_error", "speedup", "wall_s", "twin", "health",
                                                     "recorded", "out_mcap", "errors", "foreign_actuators")},
              "recorded_files": len(summary.get("recorded_files") or []),
              "rul_score": score, "wall_s": time.perf_counter() - t_start}
    (out / "report.json").write_text(json.dumps(report, indent=1, default=str))
    (out / "stack_summary.json").write_text(json.dumps(
        {k: summary.get(k) for k in ("flags", "health", "health_history", "n_warn", "n_error", "speedup", "twin")},
        indent=1, default=str))
    _print_report(report, summary)
    from hdphm.report import write_report

    page = write_report(out, out / "report.html", title=f"hdphm demo: held-out actuator {test_id}")
    print(f"report page (open in a browser, works offline): {page}")
    return 0


def _print_report(rep: dict, summary: dict) -> None:
    aid = rep["held_out_actuator"]
    print()
    print(f"==== hdphm demo report: held-out actuator {aid} ====")
    tw = rep.get("twin") or {}
    if tw:
        print(f"twin (small PINN, ONNX in the onboard node): validation NRMSE {tw.get('nrmse_pct', float('nan')):.2f} %, "
              f"R^2 {tw.get('r2', float('nan')):.4f}")
    st = rep["stack"]
    print(f"stack: expected response from '{st.get('twin')}', replay {st.get('speedup', float('nan')):.1f}x real time, "
          f"{st.get('n_warn', 0)} WARN and {st.get('n_error', 0)} ERROR flags "
          "(onboard flags are for abrupt faults against each mission's reference; the gradual wear of this life "
          "is the prognostic node's health and RUL below)")
    flags = summary.get("flags") or []
    for f in flags[:10]:
        print(f"  flag level {f['level']} at t={f['stamp_s']:.3f} s: {f['reason']}")
    if len(flags) > 10:
        print(f"  ... {len(flags) - 10} more flags")
    for act, h in (st.get("health") or {}).items():
        if act != aid:
            continue
        keys = [k for k in ("health_index", "h_mean", "rul_p5", "rul_p50", "rul_p95", "risk") if k in h]
        print(f"  prognostic node, {act}: " + ", ".join(f"{k} {float(h[k]):.4g}" for k in keys))
    sc = rep["rul_score"]
    if "eol_mission" in sc:
        last = sc["last"]
        print(f"RUL (batch, same core as the node): at mission {last['t']:.0f} P50 {last['p50']:.1f} missions "
              f"[P5 {last['p5']:.1f}, P95 {last['p95']:.1f}]; true end of life at mission {sc['eol_mission']}")
        for label, d in (("batch", sc), ("node", sc.get("node") or {})):
            keys = [k for k in ("alpha_lambda_point", "alpha_lambda_beta", "frac_in_cone_lambda_ge_0.5",
                                "coverage_p5_p95", "cra", "ph_point", "ph_beta")
                    if k in d]
            if keys:
                print(f"  {label}: " + "; ".join(f"{k} {_fmt(d[k])}" for k in keys))
    else:
        print(f"RUL: {sc.get('note')}")
    print(f"recording: {rep['recorded_files']} per-mission MCAP files in {st.get('out_mcap')} "
          f"(each passes 'hdphm validate'); report: report.json; {rep['wall_s']:.0f} s in all")


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_fmt(x)}" for k, x in v.items()) + "}"
    return str(v)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job: simulate -> train small twin -> replay through the ROS 2 stack -> health/RUL")
    p.add_argument("--out", default="runs/demo", help="output folder (default runs/demo)")
    p.add_argument("--actuators", type=int, default=5, help="fleet size; the last actuator is held out")
    p.add_argument("--max-missions", type=int, default=400, help="missions per actuator at most (lives end at failure)")
    p.add_argument("--duration", type=float, default=8.0,
                   help="inspection mission length, s (longer than the onboard node's 5 s warm-up, or it evaluates nothing)")
    p.add_argument("--mission-hours", type=float, default=200.0,
                   help="operating hours one mission stands for (wear acceleration; larger = shorter lives)")
    p.add_argument("--twin-bags-per-actuator", type=int, default=12, help="missions per training actuator for the twin")
    p.add_argument("--epochs", type=int, default=None, help="twin epochs (default: the small preset's)")
    p.add_argument("--workers", type=int, default=2, help="simulation worker processes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain of the in-process stack (default $ROS_DOMAIN_ID or 0; use one no other ROS 2 graph uses)")
    p.add_argument("--fresh", action="store_true", help="recompute every step even if its output exists")
    p.set_defaults(func=run_demo)
