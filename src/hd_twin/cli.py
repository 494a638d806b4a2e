"""Sub-commands of the twin: ``train``, ``tune``, ``twin eval|export|show|ablation``.

Registration is cheap; torch, onnxruntime and optuna are imported inside the handlers.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _model_config(path: str | None) -> dict:
    """A model config (JSON or YAML): declared_effects, extra_terms, params (dict or YAML path), model_version, parent,
    speed_timing, twist_smoothing."""
    if not path:
        return {}
    import yaml

    p = Path(path)
    try:
        txt = p.read_text()
    except FileNotFoundError:
        raise SystemExit(f"{p}: model config not found") from None
    try:
        d = json.loads(txt) if p.suffix == ".json" else yaml.safe_load(txt)
    except Exception as e:  # noqa: BLE001 - any parse error is reported with the file
        raise SystemExit(f"{p}: cannot parse model config ({e})") from None
    if not isinstance(d, dict):
        raise SystemExit(f"{p}: model config must be a mapping")
    out = {}
    if "declared_effects" in d:
        out["declared_effects"] = list(d["declared_effects"])
    if "extra_terms" in d:
        out["extra_terms"] = list(d["extra_terms"])
    if "params" in d:
        prm = d["params"]
        if isinstance(prm, str):
            from .physics import TwinParams

            prm = TwinParams.from_yaml((p.parent / prm) if not Path(prm).is_absolute() else prm).to_dict()
        out["params"] = prm
    for k in ("model_version", "parent"):
        if k in d:
            out[k] = d[k]
    if d.get("speed_timing"):  # discovery's re-timing of the logged speeds (hd_twin.speedtiming)
        from .speedtiming import SpeedTiming

        try:
            out["speed_timing"] = SpeedTiming.from_config(d["speed_timing"], f"{p} speed_timing").to_config()
        except ValueError as e:
            raise SystemExit(str(e)) from None
    if d.get("twist_smoothing"):  # discovery's smoothing of theta_f for the twist (hd_twin.twistsmooth)
        from .twistsmooth import TwistSmoothing

        try:
            out["twist_smoothing"] = TwistSmoothing.from_config(d["twist_smoothing"],
                                                                f"{p} twist_smoothing").to_config()
        except ValueError as e:
            raise SystemExit(str(e)) from None
    return out


def _cfg_from_args(args) -> "object":
    from .train import TrainConfig

    over = dict(epochs=args.epochs, seed=args.seed, layers=args.layers, hidden=args.hidden, dropout=args.dropout,
                lr=args.lr, lambda_init=args.lambda_init, threads=args.threads,
                batch=getattr(args, "batch", None), physics_path=getattr(args, "physics_path", None))
    if args.fs_model is not None:
        over["fs_target"] = None if args.fs_model <= 0 else args.fs_model
    if args.no_scaling:
        over["adaptive_scaling"] = False
    if args.no_ramp:
        over["ramp_epochs"] = 0
    if args.fixed_lambda:
        over["lambda_mode"] = "fixed"
    feats = getattr(args, "features", None)
    if feats:
        from .data import FEATURES_V1

        over["features"] = list(FEATURES_V1) if feats == "v1" else [f.strip() for f in feats.split(",") if f.strip()]
    over.update(_model_config(args.model_config))
    return TrainConfig.from_preset(args.preset, **over)


def _add_train_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="small", choices=("small", "paper", "tiny"), help="hyper-parameter preset")
    p.add_argument("--bags", nargs="+", required=True, help="bag files or directories (searched recursively)")
    p.add_argument("--epochs", type=int)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--layers", type=int)
    p.add_argument("--hidden", type=int)
    p.add_argument("--dropout", type=float)
    p.add_argument("--lr", type=float)
    p.add_argument("--lambda-init", type=float, help="initial physics weight lambda_c")
    p.add_argument("--fixed-lambda", action="store_true", help="keep lambda_c fixed (with --lambda-init 0: pure data)")
    p.add_argument("--no-scaling", action="store_true", help="switch off adaptive residual scaling")
    p.add_argument("--no-ramp", action="store_true", help="switch off the physics ramp")
    p.add_argument("--fs-model", type=float, help="model sample rate [Hz] (0 = the bags' rate)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--batch", type=int, help="windows per optimiser step (default: the preset's)")
    p.add_argument("--physics-path", choices=("auto", "identified", "none"),
                   help="the twin's physics path: the torque balance identified on the training units (auto: when "
                        "hd_twin.identify is available) plus a gated LSTM remainder, or none (the LSTM predicts Q_red)")
    p.add_argument("--features", help="network input features, comma-separated names of hd_twin.data.FEATURES "
                   "(default all); 'v1' = the 13 features of models before the torsion/friction features")
    p.add_argument("--model-config", help="JSON/YAML with declared_effects, extra_terms, params, model_version")


def _train(args) -> int:
    import torch  # noqa: F401

    from .train import load_missions, train_twin

    cfg = _cfg_from_args(args)
    missions = load_missions(args.bags)
    res = train_twin(missions, args.out, cfg)
    v = res.metrics["validation"]
    print(f"validation (held-out actuators): NRMSE {v['nrmse_pct']:.3f} %  R^2 {v['r2']:.5f}  max err {v['max_err']:.4g} N*m")
    print(f"physics path alone:              NRMSE {v['physics_only']['nrmse_pct']:.3f} %  R^2 {v['physics_only']['r2']:.5f}"
          f"  (learned remainder gate {v.get('gate', 1.0):.3f})")
    print(f"training time {res.metrics['train_time_s']:.1f} s on {res.metrics['torch_threads']} thread(s); model in {args.out}")
    return 0


def _tune(args) -> int:
    from .tune import run_study

    best = run_study(args.bags, n_trials=args.trials, storage=args.storage, study_name=args.study, out_dir=args.out,
                     epochs=args.epochs, seed=args.seed, threads=args.threads, base_preset=args.preset,
                     worker=args.worker)
    print(json.dumps(best, indent=2))
    return 0


def _eval(args) -> int:
    from .train import eval_model, load_missions

    met = eval_model(args.model, load_missions(args.bags))
    print(json.dumps(met, indent=2))
    if args.json:
        Path(args.json).write_text(json.dumps(met, indent=2))
    return 0


def _export(args) -> int:
    from .export import export_onnx

    print(export_onnx(args.model, args.out))
    return 0


def _show(args) -> int:
    d = Path(args.model)
    from .modeldir import read_config

    try:
        cfg = read_config(d)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    met = json.loads((d / "metrics.json").read_text()) if (d / "metrics.json").exists() else {}
    print(f"model {d}  version {cfg['model_version']}  arch {cfg['arch']}")
    print(f"declared effects: {cfg['declared_effects']}  extra terms: {len(cfg.get('extra_terms', []))}")
    st = {k: v for k, v in (cfg.get("speed_timing") or {}).items() if k != "window_s"}
    print("speed timing: " + (", ".join(f"{k} re-timed by {v['tau_s'] * 1e3:.3g} ms" for k, v in st.items()) or "as logged"))
    ts = cfg.get("twist_smoothing") or {}
    print("twist: " + (f"theta_f smoothed over {ts['window_s'] * 1e3:.3g} ms (Savitzky-Golay, order {ts.get('polyorder', 2)})"
                       if ts.get("window_s") else "theta_f as logged"))
    if met:
        v = met["validation"]
        print(f"validation NRMSE {v['nrmse_pct']:.3f} %  R^2 {v['r2']:.5f}  max err {v['max_err']:.4g} N*m")
    return 0


def _ablation(args) -> int:
    from .ablation import run_ablation

    run_ablation(args.bags, args.out, condition=args.condition, preset=args.preset, epochs=args.epochs,
                 seeds=args.seeds, threads=args.threads, quantile=args.quantile)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train the physics-informed LSTM twin on bags")
    _add_train_args(p)
    p.add_argument("--out", required=True, help="model directory to write")
    p.set_defaults(func=_train)

    p = sub.add_parser("tune", help="Bayesian (TPE) hyper-parameter search of the twin with Optuna")
    p.add_argument("--bags", nargs="+", required=True)
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--storage", help="Optuna storage URL (default sqlite:///OUT/study.db; resumable)")
    p.add_argument("--study", default="hd_twin", help="study name")
    p.add_argument("--worker", type=int, default=0,
                   help="this process's number when several share one --storage study (own sampler seed)")
    p.add_argument("--out", required=True)
    p.add_argument("--preset", default="small", choices=("small", "paper", "tiny"), help="base preset for the fixed settings")
    p.add_argument("--epochs", type=int, help="epochs per trial (default: the preset's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.set_defaults(func=_tune)

    tw = sub.add_parser("twin", help="digital twin: eval, export, show, ablation")
    ts = tw.add_subparsers(dest="twin_command", metavar="SUB")
    p = ts.add_parser("eval", help="metrics of a trained twin on bags")
    p.add_argument("model")
    p.add_argument("bags", nargs="+")
    p.add_argument("--json", help="also write the metrics here")
    p.set_defaults(func=_eval)
    p = ts.add_parser("export", help="(re-)export a trained twin to ONNX for streaming")
    p.add_argument("model")
    p.add_argument("--out", help="ONNX path (default MODEL/twin.onnx)")
    p.set_defaults(func=_export)
    p = ts.add_parser("show", help="print a model's config and metrics summary")
    p.add_argument("model")
    p.set_defaults(func=_show)
    p = ts.add_parser("ablation", help="PINN vs lambda_c = 0 on held-out conditions outside the training range")
    p.add_argument("--bags", nargs="+", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--condition", default="load", choices=("load", "temperature", "wear"),
                   help="which condition to extrapolate in (measured from the data, never from /sim)")
    p.add_argument("--quantile", type=float, default=0.75, help="missions above this quantile of the condition are held out")
    p.add_argument("--preset", default="small", choices=("small", "paper", "tiny"))
    p.add_argument("--epochs", type=int)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--threads", type=int, default=2)
    p.set_defaults(func=_ablation)
    tw.set_defaults(func=lambda a: (tw.print_help(), 2)[1])
