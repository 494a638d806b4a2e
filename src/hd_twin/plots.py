"""PNG figures of a training run (paper Figures 4-7 + the lambda_c trajectory)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _timeseries(path: Path, segs, preds, title: str, max_s: float = 20.0) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 3.6))
    t0 = 0.0
    for s, p in zip(segs, preds):
        n = min(s.n, int(max_s / s.dt) - int(t0 / s.dt))
        if n <= 0:
            break
        t = t0 + np.arange(n) * s.dt
        ax.plot(t, np.where(s.mask[:n], s.Q_red[:n], np.nan), "k", lw=1.0, label="measured" if t0 == 0 else None)
        ax.plot(t, p[:n], "C1--", lw=1.0, label="twin" if t0 == 0 else None)
        t0 = t[-1] + s.dt
    ax.set_xlabel("time in the shown segments [s]")
    ax.set_ylabel("Q_red [N m]")
    ax.set_title(title)
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def scatter(path: Path, y_true: np.ndarray, y_pred: np.ndarray, title: str, max_points: int = 20000) -> None:
    plt = _plt()
    ok = np.isfinite(y_true) & np.isfinite(y_pred)
    yt, yp = y_true[ok], y_pred[ok]
    if len(yt) > max_points:
        sel = np.random.default_rng(0).choice(len(yt), max_points, replace=False)
        yt, yp = yt[sel], yp[sel]
    fig, ax = plt.subplots(figsize=(4.8, 4.6))
    ax.plot(yt, yp, ".", ms=1.5, alpha=0.4)
    lim = [float(min(yt.min(), yp.min())), float(max(yt.max(), yp.max()))] if len(yt) else [0, 1]
    ax.plot(lim, lim, "k-", lw=0.8)
    ax.set_xlabel("measured Q_red [N m]")
    ax.set_ylabel("predicted Q_red [N m]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def losses(path: Path, hist: dict) -> None:
    plt = _plt()
    ep = hist["epoch"]
    fig, axs = plt.subplots(1, 3, figsize=(12, 3.4))
    for ax, key, name in zip(axs, ("total", "data", "physics"), ("L_tot", "L_d", "L_c (fixed scales)")):
        ax.semilogy(ep, hist[f"train_{key}"], label="train")
        ax.semilogy(ep, hist[f"val_{key}"], label="validation")
        ax.set_title(name)
        ax.set_xlabel("epoch")
        ax.grid(alpha=0.3, which="both")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def lambda_trajectory(path: Path, hist: dict) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.2))
    steps = hist.get("lambda_c_steps") or hist["lambda_c"]
    ax.semilogy(np.arange(1, len(steps) + 1), steps)
    ax.set_xlabel("optimiser step")
    ax.set_ylabel("lambda_c")
    ax.set_title("learned physics weight")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_training(out: Path, pinn, norm, tr_segs: Sequence, va_segs: Sequence, hist: dict, outs=None) -> None:
    """``outs``: (training, validation) network outputs already computed (hd_twin.train.predict_outputs),
    reused instead of predicting again."""
    out = Path(out)
    if outs is not None:
        from .modeldir import q_from_outputs  # noqa: PLC0415

        ptr = q_from_outputs(pinn, tr_segs[:3], outs[0][:3])
        pva = q_from_outputs(pinn, va_segs, outs[1])
    else:
        from .modeldir import predict_segments  # noqa: PLC0415

        ptr = predict_segments(pinn, tr_segs[:3], norm)
        pva = predict_segments(pinn, va_segs, norm)
    _timeseries(out / "fig4_train_torque.png", tr_segs[:3], ptr, "training set: reducer output torque")
    _timeseries(out / "fig5_val_torque.png", va_segs, pva, "validation set (held-out): reducer output torque")
    yt = np.concatenate([np.where(s.mask, s.Q_red, np.nan) for s in va_segs])
    scatter(out / "fig6_scatter.png", yt, np.concatenate(pva), "validation: predicted vs measured")
    losses(out / "fig7_losses.png", hist)
    lambda_trajectory(out / "lambda_c.png", hist)
