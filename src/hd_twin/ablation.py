"""Ablation: the PINN against the same network with lambda_c = 0, out of the training range.

Missions are ranked by a *measured* condition (never the /sim ground truth):

* ``load``: the 95th percentile of |Q_red| over the mission;
* ``temperature``: the mean gearbox (else winding) temperature;
* ``wear``: the actuator's operating hours at the mission start (metadata).

Missions above the ``quantile`` of the condition are held out as the
out-of-distribution test set; the remaining missions are split 75/25 at
actuator level into training and in-range validation. Both variants get the
same architecture, data, seed and epochs; only the physics term differs
(``lambda_c`` learnable from its initial value vs fixed at 0). Reported:
NRMSE / R^2 / max error of Q_red on the in-range validation and on the
out-of-range set, per seed, with a PNG bar chart. Whichever wins is reported.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Sequence

import numpy as np


def condition_value(m, condition: str) -> float:
    if condition == "load":
        q = np.abs(m.Q_red[np.isfinite(m.Q_red)])
        return float(np.percentile(q, 95)) if len(q) else float("nan")
    if condition == "temperature":
        T = m.temperature_on_t("gearbox")
        return float(np.nanmean(T)) if np.isfinite(T).any() else float("nan")
    if condition == "wear":
        return float(m.meta.operating_hours)
    raise ValueError(f"unknown ablation condition {condition!r}; one of load, temperature, wear")


def ood_split(missions: Sequence, condition: str, quantile: float = 0.75) -> tuple[list[int], list[int], float]:
    """(in-range indices, out-of-range indices, threshold) by the measured condition."""
    v = np.array([condition_value(m, condition) for m in missions])
    if not np.isfinite(v).all():
        bad = [missions[i].report.path for i in np.flatnonzero(~np.isfinite(v))]
        raise ValueError(f"condition {condition!r} cannot be measured in {bad}")
    thr = float(np.quantile(v, quantile))
    ood = [i for i in range(len(v)) if v[i] > thr]
    ind = [i for i in range(len(v)) if v[i] <= thr]
    if not ood or len(ind) < 2:
        raise ValueError(f"condition {condition!r} does not separate the missions (values {np.unique(v)[:8]}...)")
    return ind, ood, thr


def run_ablation(bags, out_dir: str | Path, condition: str = "load", preset: str = "small", epochs: int | None = None,
                 seeds: Sequence[int] = (0,), threads: int = 1, quantile: float = 0.75, missions: Sequence | None = None,
                 progress: bool = True) -> dict:
    from . import data as D
    from .train import TrainConfig, evaluate, load_missions, mission_label, train_twin

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if missions is None:
        missions = load_missions(bags, progress=progress)
    ind, ood, thr = ood_split(missions, condition, quantile)
    sub = [missions[i] for i in ind]
    keys = [(str(m.meta.actuator_id), mission_label(m)) for m in sub]
    rows = []
    for seed in seeds:
        tr, va = D.split_missions(keys, 0.25, seed)
        for variant, over in (("pinn", {}), ("data_only", {"lambda_mode": "fixed", "lambda_init": 0.0})):
            cfg = TrainConfig.from_preset(preset, epochs=epochs, seed=seed, threads=threads, export_onnx=False,
                                          plots=False, **over)
            if progress:
                print(f"[ablation {condition}] seed {seed} variant {variant}", file=sys.stderr, flush=True)
            res = train_twin(sub, None, cfg, split=(tr, va), progress=progress)
            fs_model = res.config["preprocessing"]["fs_model"]
            segs = [s for i in ood for s in D.preprocess(missions[i], fs_model, T_ref=res.pinn.params.T_ref,
                                                         speed_timing=res.config.get("speed_timing"),
                                                         twist_smoothing=res.config.get("twist_smoothing"))]
            m_ood = evaluate(res.pinn, segs, res.norm)
            rows.append({"seed": seed, "variant": variant, "in_range": res.metrics["validation"], "out_of_range": m_ood,
                         "train_time_s": res.metrics["train_time_s"], "lambda_c_final": res.metrics["lambda_c_final"]})
    summary = {}
    for variant in ("pinn", "data_only"):
        r = [x for x in rows if x["variant"] == variant]
        summary[variant] = {
            f"{where}_{k}": float(np.mean([x[where][k] for x in r]))
            for where in ("in_range", "out_of_range") for k in ("nrmse_pct", "r2", "max_err")
        }
    winner = min(summary, key=lambda v: summary[v]["out_of_range_nrmse_pct"])
    report = {"condition": condition, "quantile": quantile, "threshold": thr, "n_in_range": len(ind), "n_out_of_range": len(ood),
              "out_of_range_bags": [mission_label(missions[i]) for i in ood], "preset": preset, "seeds": list(seeds),
              "runs": rows, "summary": summary, "winner_out_of_range": winner}
    (out / f"ablation_{condition}.json").write_text(json.dumps(report, indent=2))
    _plot(out / f"ablation_{condition}.png", summary, condition)
    print(f"ablation ({condition} above {thr:.4g}; {len(ood)} held-out missions, seeds {list(seeds)}):")
    for v, s in summary.items():
        print(f"  {v:10s} in-range NRMSE {s['in_range_nrmse_pct']:.3f} %   out-of-range NRMSE {s['out_of_range_nrmse_pct']:.3f} %"
              f"  R^2 {s['out_of_range_r2']:.5f}  max err {s['out_of_range_max_err']:.4g} N*m")
    print(f"  better out of range: {winner}")
    return report


def _plot(path: Path, summary: dict, condition: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    names = list(summary)
    x = np.arange(2)
    for k, v in enumerate(names):
        ax.bar(x + 0.38 * k, [summary[v]["in_range_nrmse_pct"], summary[v]["out_of_range_nrmse_pct"]], 0.38, label=v)
    ax.set_xticks(x + 0.19, ["in range (validation)", f"out of range ({condition})"])
    ax.set_ylabel("NRMSE of Q_red [%]")
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
