"""Bayesian hyper-parameter search of the twin (Optuna TPE).

Searched: LSTM layers, hidden units, dropout, learning rate and the initial
physics weight lambda_c (the paper's Table 1 quantities). Objective: the
validation NRMSE of Q_red on held-out actuators (the same actuator-level split
for every trial, fixed by ``seed``). Intermediate values are reported per
epoch so the median pruner can stop poor trials early. The study lives in any
Optuna storage URL; default ``sqlite:///OUT/study.db`` so an interrupted
search resumes where it stopped and several machines can share a study: start
``hdphm tune --storage URL --study NAME --worker K`` once per process or machine
(K = 0, 1, ... gives each its own sampler seed, so they do not propose the same
trials); with a database server (``postgresql://user:pass@host/db``) that is
all, with SQLite the processes must share the file's filesystem (docs/FLEET.md).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Sequence

SPACE = {
    "layers": (1, 3),
    "hidden": (16, 512),
    "dropout": (0.0, 0.5),
    "lr": (1e-4, 1e-2),
    "lambda_init": (1e-3, 1.0),
}


def suggest(trial, space: dict = SPACE) -> dict:
    return {
        "layers": trial.suggest_int("layers", *space["layers"]),
        "hidden": trial.suggest_int("hidden", *space["hidden"], log=True),
        "dropout": trial.suggest_float("dropout", *space["dropout"]),
        "lr": trial.suggest_float("lr", *space["lr"], log=True),
        "lambda_init": trial.suggest_float("lambda_init", *space["lambda_init"], log=True),
    }


def _rdb_storage(optuna, url: str, tries: int = 6):
    """An RDB storage for ``url``, retried: processes starting together race to create the schema (the
    loser gets an IntegrityError / OperationalError and finds the schema made on the next try)."""
    import time

    from sqlalchemy.exc import IntegrityError, OperationalError

    for k in range(tries):
        try:
            return optuna.storages.RDBStorage(
                url, engine_kwargs={"connect_args": {"timeout": 60}} if url.startswith("sqlite") else {},
                heartbeat_interval=60, grace_period=180)
        except (IntegrityError, OperationalError):
            if k == tries - 1:
                raise
            time.sleep(0.5 * (k + 1))
    raise AssertionError("unreachable")


def run_study(bags: Sequence[str] | Sequence, n_trials: int, storage: str | None, study_name: str, out_dir: str | Path,
              epochs: int | None = None, seed: int = 0, threads: int = 1, base_preset: str = "small",
              missions: Sequence | None = None, space: dict = SPACE, worker: int = 0) -> dict:
    """Run (or resume) a TPE study; writes ``OUT/best.json`` and trains nothing else. Returns the best trial."""
    import optuna

    from . import data as D
    from .train import TrainConfig, load_missions, mission_label, train_twin

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    storage = storage or f"sqlite:///{(out / 'study.db').resolve()}"
    if missions is None:
        missions = load_missions(bags)
    keys = [(str(m.meta.actuator_id), mission_label(m)) for m in missions]
    split = D.split_missions(keys, 0.25, seed)
    if not 0 <= int(worker) < 10**6:
        raise ValueError(f"tune: worker number {worker} must be in 0..1e6")
    # each worker process of a shared study gets its own sampler seed (else they propose the same trials)
    sampler = optuna.samplers.TPESampler(seed=seed + 7919 * int(worker), n_startup_trials=min(5, max(1, n_trials // 3)))
    if isinstance(storage, str) and storage.startswith(("sqlite", "postgresql", "mysql")):
        # several processes on one study: wait for SQLite's lock instead of failing; a heartbeat marks the
        # running trials of a killed process FAIL so they do not stay RUNNING forever
        storage = _rdb_storage(optuna, storage)
    study = optuna.create_study(study_name=study_name, storage=storage, direction="minimize", sampler=sampler,
                                pruner=optuna.pruners.MedianPruner(n_startup_trials=3, n_warmup_steps=2),
                                load_if_exists=True)

    def objective(trial):
        hp = suggest(trial, space)
        cfg = TrainConfig.from_preset(base_preset, epochs=epochs, seed=seed, threads=threads, export_onnx=False,
                                      plots=False, **hp)

        def cb(ep, rec):
            trial.report(rec["val_data"], ep)
            if trial.should_prune():
                raise optuna.TrialPruned()

        res = train_twin(missions, None, cfg, split=split, progress=False, epoch_callback=cb)
        v = res.metrics["validation"]
        trial.set_user_attr("r2", v["r2"])
        trial.set_user_attr("max_err", v["max_err"])
        trial.set_user_attr("train_time_s", res.metrics["train_time_s"])
        print(f"trial {trial.number}: {hp} -> NRMSE {v['nrmse_pct']:.3f} %  R^2 {v['r2']:.5f}", file=sys.stderr, flush=True)
        return v["nrmse_pct"]

    done = len([t for t in study.trials if t.state.is_finished()])
    print(f"study {study_name!r} in {getattr(storage, 'url', storage)}: {done} finished trials, running {n_trials} more", file=sys.stderr)
    study.optimize(objective, n_trials=n_trials, catch=(FloatingPointError,))
    best = {"study": study_name, "storage": getattr(storage, "url", storage), "worker": int(worker), "n_trials": len(study.trials),
            "best_value_nrmse_pct": study.best_value, "best_params": study.best_params,
            "best_user_attrs": study.best_trial.user_attrs}
    (out / "best.json").write_text(json.dumps(best, indent=2))
    return best
