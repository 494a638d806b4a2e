"""``hdphm discover``: bags (+ optional twin model dir) -> report.json, plots, new twin version.

Thin I/O around :mod:`hd_ground.discovery.core`. Reads contract bags with
``hd_bag.read_mission`` (never ``/sim``), runs discovery per target signal,
writes ``OUT/report.json`` (schema in this package's README.md), PNG plots
and ``OUT/twin/config.json``: the new model version with the found effects
declared and their terms in ``extra_terms``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

import numpy as np

from hd_bag.files import find_bags
from hd_bag.jsonsafe import json_safe

from .core import (DEFAULT_DECLARED, Options, SignalResult, angle_skew_of, choose_alpha_window, choose_angle_timing,
                   choose_retime_window, choose_speed_timing, choose_twist_window, confirm_twist_window,
                   discover_signal, split_fit_heldout, static_term, uses_angle_harmonic)
from .data import (DEFAULT_ALPHA_WINDOW_S, Dataset, DiscoveryError, dataset_from_missions, with_angle_skew,
                   with_smoothed_twist)

#: Twin declared effects that are model structure, not candidate effects of a target signal.
STRUCTURAL = {"inertia", "linear_stiffness", "structural_damping", "mesh_friction"}
REPORT_FORMAT = "hdphm-discovery/1"


def load_twin(model_dir: str | Path) -> dict:
    """The twin's config.json as a dict (declared_effects, params, extra_terms, model_version)."""
    from hd_twin.modeldir import CONFIG_NAME, read_config

    p = Path(model_dir) / CONFIG_NAME
    try:
        cfg = read_config(model_dir)
    except ValueError as e:
        raise DiscoveryError(str(e)) from None
    if not isinstance(cfg.get("declared_effects", []), list):
        raise DiscoveryError(f"{p}: declared_effects must be a list")
    from hd_twin.terms import validate_term

    for i, t in enumerate(cfg.get("extra_terms", []) or []):
        try:
            validate_term(t, f"{p} extra_terms[{i}]")
        except ValueError as e:
            raise DiscoveryError(str(e)) from None
    return cfg


def expand_paths(paths: list[str]) -> list[Path]:
    """Bag files from files and directories (``*.mcap``, sorted); errors name the path
    (:func:`hd_bag.files.find_bags`)."""
    return find_bags(paths, empty_dir_error=True, empty_error=False, error=DiscoveryError)


def run_discovery(
    bags: list[str],
    out_dir: str | Path,
    *,
    twin_dir: str | None = None,
    signals: list[str] | None = None,
    heldout: list[str] | None = None,
    heldout_frac: float = 0.3,
    blocks_per_bag: int = 5,
    within_bag_check: bool = True,
    opt: Options | None = None,
    plots: bool = True,
    retrain: bool = False,
    log=print,
    missions=None,
    results_out: list | None = None,
) -> dict:
    """Run discovery on ``bags`` and write OUT_DIR; returns the report dict.

    ``heldout``: bag names/paths (or substrings) held out whole; default: the
    last bag when there are several, else the last ``heldout_frac`` of time of
    each bag. ``missions`` (already read, same order as ``bags``) skips reading. ``results_out``: a list
    that receives the per-signal :class:`SignalResult` objects (held-out residual arrays for evaluations).
    """
    opt = opt or Options()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if missions is None:
        from hd_bag import read_mission

        paths = expand_paths(bags)
        missions = []
        for p in paths:
            log(f"reading {p}")
            missions.append(read_mission(str(p)))
        names = [str(p) for p in paths]
    else:
        names = [str(b) for b in bags]
    ds = dataset_from_missions(missions, names, blocks_per_bag=blocks_per_bag)
    # the acquisition skew of the torque sample after the angle's, from the identified speed lags (whether or not
    # the re-timed speeds are then used): the candidate re-timing of the position harmonics (choose_angle_timing)
    if opt.retime_window not in ("identify", "default"):
        raise DiscoveryError(f"Options.retime_window must be 'identify' or 'default', not {opt.retime_window!r}")
    if opt.angle_timing not in ("identify", "default", "retimed"):
        raise DiscoveryError(f"Options.angle_timing must be 'identify', 'default' or 'retimed', not {opt.angle_timing!r}")
    skew = angle_skew_of(ds.speed_lags) if opt.angle_timing != "default" else None
    lag_m = (ds.speed_lags or {}).get("omega_m")
    if opt.angle_timing != "default" and skew is None and lag_m is not None and lag_m > 0:  # a lagging speed
        ds.notes.append(f"angle timing: the logged omega_m lags the angle's rate by {lag_m * 1e3:.3g} ms (a filtered "
                        "speed estimate, not an acquisition skew of the torque sample): position harmonics taken at "
                        "the logged angle, no re-timing tried")

    twin = load_twin(twin_dir) if twin_dir else None
    declared_all = list(twin.get("declared_effects", [])) if twin else None
    extra = list(twin.get("extra_terms", []) or []) if twin else []
    tparams = dict(twin.get("params", {}) or {}) if twin else {}
    if "stribeck_delta" in tparams:
        tparams.setdefault("delta", tparams["stribeck_delta"])

    ho_bags: list[int] = []
    if heldout:
        for h in heldout:
            hit = [i for i, n_ in enumerate(names) if h == n_ or h in n_]
            if not hit:
                raise DiscoveryError(f"--heldout {h!r} matches none of the bags {names}")
            ho_bags += hit
    elif len(names) > 1:
        ho_bags = [len(names) - 1]
    ho_bags = sorted(set(ho_bags))
    if ho_bags and len(ho_bags) == len(names):
        raise DiscoveryError("every bag is held out; leave at least one bag to fit on")
    ho = split_fit_heldout(ds, ho_bags, heldout_frac)
    if ds.speed_lags:
        # the identified speed delays are used only when the fit bags' tau_m baseline prefers them
        ds, st_ = choose_speed_timing(dataset_from_missions(missions, names, blocks_per_bag=blocks_per_bag,
                                                            retime_speeds=False), ds, ho, opt)
        ds.notes.append(st_)
    if ds.speed_lags and opt.retime_window != "default":
        # the re-timing's derivative window, by the same rule on the fit bags (core.choose_retime_window)
        ds, st_ = choose_retime_window(lambda win: dataset_from_missions(
            missions, names, blocks_per_bag=blocks_per_bag, retime_window_s=win), ds, ho, opt)
        if st_:
            ds.notes.append(st_)
    if opt.alpha_window != "default":
        # the acceleration's timing (and window), by the same rule on the fit bags (same speeds as chosen above)
        ds, st_ = choose_alpha_window(lambda win, timing, re=bool(ds.speed_lags), rw=ds.speed_window_s:
                                      dataset_from_missions(missions, names, blocks_per_bag=blocks_per_bag,
                                                            retime_speeds=re, alpha_window_s=win, alpha_timing=timing,
                                                            retime_window_s=rw), ds, ho, opt, mode=opt.alpha_window)
        if st_:
            ds.notes.append(st_)
    for n_ in ds.notes:
        log(f"note: {n_}")
    split = ({"mode": "bags", "heldout": [names[i] for i in ho_bags]} if ho_bags
             else {"mode": "time_blocks", "heldout_frac": heldout_frac, "blocks_per_bag": blocks_per_bag})

    targets = signals or ["tau_m"] + (["Q_red"] if "Q_red" in ds.signals else [])
    results: list[SignalResult] = []
    twist_window = 0  # theta_f's smoothing window for the twist of the Q_red models (0: as logged)
    angle_skews: dict[str, float] = {}  # target -> the acquisition skew its position harmonics were taken with
    for target in targets:
        if target not in ds.signals:
            log(f"{target}: not measured in these bags; skipped")
            continue
        decl = None if declared_all is None else [e for e in declared_all if e not in STRUCTURAL and _applies(e, target)]
        if decl is None:
            decl = list(DEFAULT_DECLARED[target])
        log(f"{target}: discovering (declared: {decl or 'none'}) ...")
        res = discover_signal(ds, target, ho, declared=decl, extra_terms=extra, twin_params=tparams, opt=opt)
        ds_res = ds  # the dataset res was selected on
        if target == "Q_red" and opt.twist_window != "default":
            # the twist's output angle, smoothed or as logged, chosen on the fit bags with the model just selected
            # (core.choose_twist_window); when a smoother is identified, the Q_red discovery is made again with it
            ds_q, st_ = choose_twist_window(ds, ho, opt, terms=res.terms, declared=decl, extra_terms=extra)
            if st_:
                ds.notes.append(st_)
                log(f"note: {st_}")
            if ds_q is not ds:
                res_s = discover_signal(ds_q, target, ho, declared=decl, extra_terms=extra, twin_params=tparams,
                                        opt=opt)
                # the smoother must hold for the model finally selected on it too: the two final models compared
                # on the fit bags by the same rule (core.confirm_twist_window); otherwise the logged twist stays
                keep, st_ = confirm_twist_window(ds, ds_q, ho, opt, terms_logged=res.terms, terms_smoothed=res_s.terms,
                                                 declared=decl, extra_terms=extra)
                if st_:
                    ds.notes.append(st_)
                    log(f"note: {st_}")
                if keep:
                    res = res_s
                    twist_window = int(ds_q.twist_window)
                    ds_res = ds_q
        if skew is not None and uses_angle_harmonic(res.terms):
            # the selected model holds a position harmonic: the discovery is made again with every harmonic taken
            # at the angle re-timed by the acquisition skew, and the fit bags' CV of the two final models decides
            # (core.choose_angle_timing)
            res_a = discover_signal(with_angle_skew(ds_res, skew), target, ho, declared=decl, extra_terms=extra,
                                    twin_params=tparams, opt=opt)
            keep, st_ = choose_angle_timing(res, res_a, skew, opt)
            ds.notes.append(st_)
            log(f"note: {st_}")
            if keep:
                res = res_a
                angle_skews[target] = float(skew)
        results.append(res)
        if results_out is not None:
            results_out.append(res)
        _log_result(res, log)

    within = {}
    if within_bag_check and ho_bags:
        # second, independent run: fit bags only, last time blocks of each held out
        fit_only = ds.subset(~np.isin(ds.bag, ho_bags))
        if twist_window:
            fit_only = with_smoothed_twist(fit_only, twist_window)
        ho2 = split_fit_heldout(fit_only, None, heldout_frac)
        for target in [r.signal for r in results if r.identifiable]:
            decl = [r.declared_before for r in results if r.signal == target][0]
            o2 = Options(**{**asdict(opt), "angle_offset": "none"})
            fo = with_angle_skew(fit_only, angle_skews[target]) if target in angle_skews else fit_only
            r2 = discover_signal(fo, target, ho2, declared=decl, extra_terms=extra, twin_params=tparams, opt=o2)
            within[target] = {"error_before": r2.error_before, "error_after": r2.error_after,
                              "effects": [_effect_brief(e) for e in r2.effects], "heldout_frac": heldout_frac}

    report = build_report(results, split, ds, within, twin_dir, opt)
    # the twist the Q_red models were fitted with (core.choose_twist_window): theta_f's smoothing window in
    # samples, 0 as logged (the new twin version's config.json:twist_smoothing carries it in seconds)
    report["twist_window_samples"] = twist_window
    # the acquisition skew each target's position harmonics were taken with (core.choose_angle_timing; the terms'
    # sin / cos bases carry it as "skew_s" with their angle's "rate", so the twin evaluates them the same way)
    report["angle_skew_s"] = dict(angle_skews)
    new_dir = write_twin_version(out / "twin", twin, twin_dir, results, retrain=retrain, missions=missions, log=log,
                                 speed_lags=ds.speed_lags, speed_window_s=ds.speed_window_s,
                                 acceleration=report["acceleration"],
                                 twist_window=twist_window, angle_skews=angle_skews)
    report["twin_out"] = str(new_dir) if new_dir else None
    if plots and results:
        from .plots import plot_result

        for r in results:
            if r.identifiable:
                report.setdefault("plots", []).extend(plot_result(r, out, ds))
    (out / "report.json").write_text(json.dumps(json_safe(report), indent=2))
    log(f"report: {out / 'report.json'}")
    return report


def _applies(effect: str, target: str) -> bool:
    q_only = {"kinematic_error_harmonic", "position_dependent_stiffness", "nonlinear_stiffness", "hysteresis", "backlash"}
    return (effect in q_only) == (target == "Q_red")


def _effect_brief(e: dict) -> dict:
    return {k: e[k] for k in ("name", "variable", "order", "explained")}


def _log_result(r: SignalResult, log) -> None:
    for s in r.statements:
        log(f"  {r.signal}: {s}")
    if not r.identifiable:
        return
    for e in r.effects:
        ps = ", ".join(f"{k}={v:.4g}" for k, v in e["parameters"].items())
        log(f"  found {e['name']} ({e['variable']}, order {e['order']}): {e['form']}; {ps}; "
            f"explains {e['explained']:.1%} of held-out residual variance")
    log(f"  held-out {r.signal} RMSE {r.error_before['rmse']:.4g} -> {r.error_after['rmse']:.4g} N*m "
        f"(NRMSE {r.error_before['nrmse']:.3g} -> {r.error_after['nrmse']:.3g})")


def build_report(results: list[SignalResult], split: dict, ds: Dataset, within: dict, twin_dir, opt: Options) -> dict:
    per = []
    for r in results:
        per.append({
            "signal": r.signal, "identifiable": r.identifiable, "statements": r.statements,
            "error_before": r.error_before, "error_after": r.error_after, "effects": r.effects,
            "declared_before": r.declared_before, "declared_after": r.declared_after,
            "baseline_parameters": r.baseline_params, "refit_baseline_parameters": r.refit_baseline_params,
            "terms": r.terms, "angle_offsets": r.offsets, "comparisons": r.comparisons,
            "selection_trace": r.cv_trace,
            # the friction width's second look with a width-re-identifying group (Stribeck) left out (core.
            # _reidentify_width; empty: not asked that way)
            "width_second_look": r.width_second_look,
            "order_spectra": [{"variable": s.variable, "modulator": s.modulator, "peaks": s.peaks,
                               "floor": s.floor, "revolutions": s.revolutions} for s in r.spectra],
            # theta_m orders found by the band-limited line search (spectrum.band_line_scan), tried as candidates
            "band_lines": [{"order": b.order, "cv_gain": b.gain, "paired_t": b.t, "z": b.z, "v_b": b.v_b,
                            "revolutions": b.revolutions} for b in r.band_lines],
            "within_bag": within.get(r.signal),
        })
    primary = next((p for p in per if p["identifiable"] and p["effects"]), None) or \
        next((p for p in per if p["identifiable"]), None) or (per[0] if per else None)
    rep = {"format": REPORT_FORMAT, "bags": ds.bag_names, "split": split, "twin_in": twin_dir,
           "options": asdict(opt), "signals": per, "data_notes": list(ds.notes),
           "speed_lags": dict(ds.speed_lags),
           # the re-timing's derivative window the speed lags were identified and applied with (core.choose_retime_window;
           # None: speeds used as logged)
           "speed_window_s": float(ds.speed_window_s) if ds.speed_lags else None,
           # the motor acceleration the models were fitted with (core.choose_alpha_window)
           "acceleration": dict(ds.alpha_window) or {"window_s": DEFAULT_ALPHA_WINDOW_S, "timing": False}}
    if primary:
        for k in ("signal", "error_before", "error_after", "effects", "declared_before", "declared_after",
                  "identifiable", "statements"):
            rep[k] = primary[k]
        # all signals' effects, best first, in the top-level list
        rep["effects"] = sorted([e for p in per for e in p["effects"]], key=lambda e: -e["explained"])
        rep["declared_after"] = list(dict.fromkeys(sum((p["declared_after"] for p in per), [])))
        rep["declared_before"] = list(dict.fromkeys(sum((p["declared_before"] for p in per), [])))
    return rep


def write_twin_version(dst: Path, twin: dict | None, twin_dir: str | None, results: list[SignalResult], *,
                       retrain: bool, missions, log, speed_lags: dict | None = None,
                       speed_window_s: float | None = None,
                       acceleration: dict | None = None, twist_window: int = 0,
                       angle_skews: dict | None = None) -> Path | None:
    """Write the augmented model version (only when something was found).

    ``speed_lags`` (``Dataset.speed_lags``: the re-timing discovery used, empty when the speeds were used as
    logged) go into ``config.json:speed_timing`` (:mod:`hd_twin.speedtiming`), so the twin evaluates the
    found terms on the speeds they were fitted on; absent = as logged. A trained network copied from the
    parent keeps the parent's entry (the inputs it was trained on) until it is retrained with the new one;
    ``discovery.speed_timing`` always records discovery's. ``acceleration`` (the derivative window and timing
    column discovery fitted with, ``core.choose_alpha_window``) is recorded in ``discovery.acceleration`` only:
    no twin input depends on it (the twin derives its own accelerations, ``hd_twin.data``; the found terms and
    the recalibrated T_C, b_visc, eps_omega are functions of speed, angle and current, and J_eq and the timing
    coefficient J tau_a are not written), so the twin needs no entry for it. ``twist_window`` (theta_f's smoothing
    for the twist of the Q_red terms, ``core.choose_twist_window``; 0: as logged; samples at the first mission's
    rate) goes into ``config.json:twist_smoothing`` (:mod:`hd_twin.twistsmooth`, the window in seconds) by the
    speed timing's rule, so the twin reads the twist the Q_red terms were fitted on; ``discovery.twist_window_samples``
    always records discovery's. ``angle_skews`` (target -> the acquisition skew its position harmonics were taken
    with, ``core.choose_angle_timing``) needs no config entry: each harmonic basis carries its ``skew_s`` and
    ``rate`` (``hd_twin.terms.retimed_angle``, evaluated per sample, so batch and streaming twins alike take it);
    ``discovery.angle_skew_s`` records it."""
    # the twin evaluates static terms sample by sample: a term on a pre-sliding state (a path history) goes
    # in its static form (hd_ground.discovery.core.static_term); one without such a form stays in the report
    new_terms, dropped = [], []
    for r in results:
        for t in r.terms:
            st = static_term(t, r.baseline_params.get("eps_omega"))
            (new_terms if st is not None else dropped).append(st if st is not None else t)
    if dropped:
        # the new version still declares them (and carries the recalibrated baseline): a found effect is never
        # silently lost from the model's record
        log(f"declared in the new twin version without a term (they need a state of the twist the twin does not "
            f"carry): {[t['name'] for t in dropped]}")
    if not new_terms and not dropped:
        log("twin unchanged (no effect found)")
        return None
    if dst.exists():
        shutil.rmtree(dst)
    if twin is not None:
        shutil.copytree(twin_dir, dst)
        cfg = json.loads(json.dumps(twin))
    else:
        dst.mkdir(parents=True)
        cfg = {"format": "hd_twin/physics-only", "model_version": 0, "declared_effects": ["inertia"] +
               DEFAULT_DECLARED["tau_m"], "extra_terms": [], "params": {}}
    parent_version = cfg.get("model_version", 0)
    cfg["parent"] = {"dir": twin_dir, "model_version": parent_version}
    cfg["model_version"] = (parent_version + 1) if isinstance(parent_version, int) else f"{parent_version}+1"
    decl = list(cfg.get("declared_effects", []))
    for r in results:
        for e in r.declared_after:
            if e not in decl:
                decl.append(e)
    cfg["declared_effects"] = decl
    cfg["extra_terms"] = list(cfg.get("extra_terms", []) or []) + new_terms
    params = dict(cfg.get("params", {}) or {})
    for r in results:
        if r.signal == "tau_m" and r.identifiable:
            rp = r.refit_baseline_params
            if "T_C" in rp and rp["T_C"] >= 0:
                params["T_C"] = rp["T_C"]
            if "b" in rp and rp["b"] >= 0:
                params["b_visc"] = rp["b"]
            if r.baseline_params.get("eps_omega", 0) > 0:
                # the identified friction transition width (hd_twin.physics' regularised sign)
                params["eps_omega"] = r.baseline_params["eps_omega"]
    cfg["params"] = params
    timing = _speed_timing_entry(speed_lags or {}, missions, speed_window_s)
    parent_timing = cfg.pop("speed_timing", None)
    if twin is not None and "normalization" in cfg and parent_timing:
        # a copied network keeps the inputs it was trained on until it is retrained (below)
        cfg["speed_timing"] = parent_timing
    if timing and not (twin is not None and "normalization" in cfg):
        cfg["speed_timing"] = timing  # physics-only version: the terms are evaluated on the speeds they were fitted on
    smoothing = _twist_smoothing_entry(twist_window, missions)
    parent_smoothing = cfg.pop("twist_smoothing", None)
    if twin is not None and "normalization" in cfg and parent_smoothing:
        cfg["twist_smoothing"] = parent_smoothing  # the copied network's inputs, until it is retrained
    if smoothing and not (twin is not None and "normalization" in cfg):
        cfg["twist_smoothing"] = smoothing  # the Q_red terms are evaluated on the twist they were fitted on
    cfg["discovery"] = {"speed_timing": timing or "speeds used as logged",
                        "acceleration": dict(acceleration or {}),
                        "twist_window_samples": int(twist_window),
                        "angle_skew_s": dict(angle_skews or {}),
                        "recalibrated": [k for k in ("T_C", "b_visc", "eps_omega") if k in params],
                        "baseline_refit": {r.signal: r.refit_baseline_params for r in results},
                        "network": "copied from the parent version, not retrained" if twin is not None else "none (physics-only model)"}
    if retrain and twin is not None and "train" in cfg:
        try:
            from hd_twin.train import TrainConfig, train_twin

            tc = dict(cfg["train"])
            tc.update(declared_effects=decl, extra_terms=cfg["extra_terms"], model_version=cfg["model_version"],
                      parent=str(twin_dir), speed_timing=dict(timing), twist_smoothing=dict(smoothing))
            fields = TrainConfig.__dataclass_fields__
            log("retraining the twin with the new effects (hd_twin.train.train_twin) ...")
            train_twin(missions, dst, TrainConfig(**{k: v for k, v in tc.items() if k in fields}))
            from hd_twin.modeldir import read_config

            cfg2 = read_config(dst)
            cfg2["discovery"] = dict(cfg["discovery"], network="retrained with the new physics terms")
            (dst / "config.json").write_text(json.dumps(json_safe(cfg2), indent=2))
            return dst
        except Exception as e:  # noqa: BLE001 - report, keep the recalibrated version
            log(f"retraining failed ({type(e).__name__}: {e}); writing the recalibrated physics only")
    (dst / "config.json").write_text(json.dumps(json_safe(cfg), indent=2))
    log(f"new twin version {cfg['model_version']} written to {dst}")
    return dst


def _twist_smoothing_entry(twist_window: int, missions) -> dict:
    """``config.json:twist_smoothing`` for discovery's smoothing of theta_f (``twist_window`` samples at the
    first mission's rate; {} when the twist was read as logged)."""
    if not twist_window or not missions:
        return {}
    from hd_twin.twistsmooth import TwistSmoothing

    return TwistSmoothing.from_samples(int(twist_window), float(missions[0].fs)).to_config()


def _speed_timing_entry(speed_lags: dict, missions, window_s: float | None = None) -> dict:
    """``config.json:speed_timing`` for the re-timing discovery applied (with each delay's standard error) and its
    derivative window ``window_s`` (``core.choose_retime_window``; None: the default 20 ms)."""
    if not speed_lags:
        return {}
    from hd_twin.speedtiming import DEFAULT_WINDOW_S, SpeedTiming

    from .data import speed_lag

    w = DEFAULT_WINDOW_S if window_s is None else float(window_s)
    angle = {"omega_m": "theta_m", "omega_f": "theta_f"}
    se = {k: speed_lag(missions, k, angle[k], window_s=w)[1] for k in speed_lags} if missions else {}
    return SpeedTiming.from_lags(speed_lags, se, window_s=w).to_config()
