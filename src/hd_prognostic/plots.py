"""Figures: alpha-lambda (paper Fig. 11), PF snapshots (Figs. 9-10), feature monotonicity/separability (Figs. 3, 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hd_prognostic.pf import weighted_quantile


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def alpha_lambda_plot(ax, t, p50, p5, p95, t_eol: float, alpha: float = 0.2, t_p: float | None = None,
                      title: str = "", unit: str = "") -> None:
    """True RUL line, alpha cone, median prediction and P5-P95 band on ``ax``."""
    t, p50, p5, p95 = (np.asarray(a, float) for a in (t, p50, p5, p95))
    sel = t <= t_eol
    t, p50, p5, p95 = t[sel], p50[sel], p5[sel], p95[sel]
    tt = np.linspace(t[0] if t_p is None else t_p, t_eol, 100)
    rt = t_eol - tt
    ax.fill_between(tt, (1 - alpha) * rt, (1 + alpha) * rt, color="tab:green", alpha=0.15,
                    label=f"alpha = {alpha:g} cone")
    ax.plot(tt, rt, "k--", lw=1, label="true RUL")
    fin = np.isfinite(p95)
    ax.fill_between(t[fin], p5[fin], p95[fin], color="tab:blue", alpha=0.25, step="post", label="P5-P95")
    ax.plot(t, p50, "o-", ms=2.5, color="tab:blue", lw=1, label="median RUL")
    tp = t[0] if t_p is None else t_p
    for lam in (0.5,):
        ax.axvline(tp + lam * (t_eol - tp), color="grey", lw=0.8, ls=":")
    ax.set_xlabel(f"time [{unit}]" if unit else "time")
    ax.set_ylabel(f"RUL [{unit}]" if unit else "RUL")
    ymax = 1.6 * (t_eol - t[0])
    ax.set_ylim(0, ymax)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper right")


def save_alpha_lambda(path, t, p50, p5, p95, t_eol, alpha=0.2, title="", unit="") -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    alpha_lambda_plot(ax, t, p50, p5, p95, t_eol, alpha, title=title, unit=unit)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def save_alpha_lambda_grid(path, histories: list, eols: list[float], alpha=0.2, unit="", ncols=3, title="") -> Path:
    plt = _plt()
    n = len(histories)
    nr = int(np.ceil(n / ncols))
    fig, axs = plt.subplots(nr, min(ncols, n), figsize=(4.2 * min(ncols, n), 3.2 * nr), squeeze=False)
    for ax, h, e in zip(axs.flat, histories, eols):
        alpha_lambda_plot(ax, h.rul_t, h.p50, h.p5, h.p95, e, alpha, title=h.unit, unit=unit)
    for ax in list(axs.flat)[n:]:
        ax.axis("off")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def save_snapshot(path, snap: dict, model, threshold: float, truth_h: float | None = None, title: str = "",
                  state_scale: float = 1.0, state_unit: str = "", time_unit: str = "") -> Path:
    """One PF snapshot (paper Figs. 9-10): state and observation distributions, RUL, risk, trajectories."""
    plt = _plt()
    x, w, z, r, paths = snap["x"], snap["w"], snap["z"], snap["rul"], snap["paths"]
    fig, axs = plt.subplots(2, 3, figsize=(13, 7))
    h = x[:, model.health_index] * state_scale
    ax = axs[0, 0]
    ax.hist(h, bins=60, weights=w, density=True, color="tab:blue", alpha=0.7, label="posterior")
    if truth_h is not None and np.isfinite(truth_h):
        ax.axvline(truth_h * state_scale, color="k", ls="--", label="truth")
    ax.set_xlabel(f"{model.state_names[model.health_index]} [{state_unit}]")
    ax.set_title("hidden state distribution")
    ax.legend(fontsize=7)
    ax = axs[0, 1]
    mu, sd = model.observe(x)
    rng = np.random.default_rng(0)
    ysim = mu + sd * rng.standard_normal(len(mu))
    ax.hist(ysim, bins=60, weights=w, density=True, color="tab:orange", alpha=0.7, label="predicted feature")
    if np.isfinite(z):
        ax.axvline(z, color="k", ls="--", label="observed")
    ax.set_title("observation distribution")
    ax.legend(fontsize=7)
    ax = axs[0, 2]
    s = r.samples[np.isfinite(r.samples)]
    ws = r.weights[np.isfinite(r.samples)]
    if len(s):
        ax.hist(s, bins=50, weights=ws, density=True, color="tab:red", alpha=0.7)
    for q, ls in ((r.p5, ":"), (r.p50, "-"), (r.p95, ":")):
        if np.isfinite(q):
            ax.axvline(q, color="k", ls=ls, lw=1)
    ax.set_xlabel(f"RUL [{time_unit}]")
    ax.set_title(f"RUL: P5 {r.p5:.0f}, P50 {r.p50:.0f}, P95 {r.p95:.0f}")
    ax = axs[1, 0]
    tg = np.linspace(0, max(np.nanmax(s) if len(s) else 1, 1), 200)
    ax.plot(tg, r.risk(tg), color="tab:red")
    ax.set_xlabel(f"time from now [{time_unit}]")
    ax.set_ylabel("P(failure before t)")
    ax.set_title("risk of failure")
    ax.grid(alpha=0.3)
    ax = axs[1, 1]
    t0 = snap["t"]
    tp = t0 + np.arange(paths.shape[0])
    ax.plot(tp, paths * state_scale, color="tab:blue", alpha=0.08, lw=0.8)
    ax.axhline(threshold * state_scale, color="r", ls="--", label="failure threshold")
    ax.set_xlabel(f"time [{time_unit}]")
    ax.set_ylabel(f"{model.state_names[model.health_index]} [{state_unit}]")
    ax.set_title("particle trajectories to threshold")
    ax.legend(fontsize=7)
    ax = axs[1, 2]
    ax.plot(snap["t_hist"], snap["z_hist"], ".", ms=3, color="tab:orange")
    ax.set_xlabel(f"time [{time_unit}]")
    ax.set_title("observed feature history")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def save_state_history(path, hist, truth_t=None, truth_h=None, state_scale=1.0, state_unit="", title="") -> Path:
    plt = _plt()
    fig, axs = plt.subplots(1, 2, figsize=(11, 3.8))
    t = np.asarray(hist.t)
    m = np.asarray(hist.state_mean)
    lo, hi = np.asarray(hist.state_p5), np.asarray(hist.state_p95)
    ax = axs[0]
    ax.fill_between(t, lo[:, 0] * state_scale, hi[:, 0] * state_scale, alpha=0.3, label="P5-P95")
    ax.plot(t, m[:, 0] * state_scale, label="PF mean")
    if truth_h is not None:
        ax.plot(truth_t, np.asarray(truth_h) * state_scale, "k--", label="truth")
    if np.isfinite(hist.threshold):
        ax.axhline(hist.threshold * state_scale, color="r", ls=":", label="threshold")
    ax.set_ylabel(f"{hist.state_names[0]} [{state_unit}]")
    ax.set_xlabel(hist.time_unit)
    ax.legend(fontsize=7)
    ax = axs[1]
    ax.plot(t, hist.z, ".", ms=3, color="tab:orange")
    ax.set_ylabel("observed feature")
    ax.set_xlabel(hist.time_unit)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def weighted_median(v, w):
    return float(weighted_quantile(v, w, 0.5)[0])
