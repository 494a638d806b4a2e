"""Evaluation on simulated fleets (reads ``/sim/health``: evaluation code only).

* :func:`feature_study` -- monotonicity and early/advanced separability of
  every health feature against the true wear (paper Figs. 3 and 8).
* :func:`fleet_eval` -- per-actuator held-out evaluation: k folds over
  actuators; the observation model and Archard prior are fitted on the
  training folds only, the PF (and the UKF baseline) run on the held-out
  actuators and are scored against the true end of life (first mission whose
  start wear reaches ``h_fail``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from hd_prognostic import metrics as M
from hd_prognostic.pipeline import (ActuatorData, build_model, extract_actuator,
                                    find_actuator_groups, fit_population, mission_sequence, prognose)
from hd_prognostic.observation import ObservationModel
from hd_prognostic.rul import rul_distribution

STUDY_FEATURES = ("HF_MTW_IF", "ke_2x", "ke_1x", "ke_4x", "lost_motion", "hysteresis", "te_rms", "ke_indicator",
                  "compliance_residual", "cs_gain", "cs_coulomb", "cs_rms_ratio", "efficiency")


def _extract_one(args):
    d, bags, cache = args
    t0 = time.perf_counter()
    return extract_actuator(d, include_truth=True, cache=cache, bags=bags), time.perf_counter() - t0


def load_fleet(fleet_dir, cache_dir=None, progress: bool = True, workers: int = 1) -> list[ActuatorData]:
    """Features + wear truth of every actuator folder (cached per actuator; ``workers`` processes)."""
    jobs = [(Path(fleet_dir) / name, bags, Path(cache_dir) / f"{name}.features.json" if cache_dir else None)
            for name, bags in find_actuator_groups(fleet_dir)]
    if workers > 1 and len(jobs) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(workers, len(jobs))) as ex:
            results = list(ex.map(_extract_one, jobs))
    else:
        results = []
        for j in jobs:
            results.append(_extract_one(j))
            if progress:
                print(f"  {j[0].name}: {len(results[-1][0].paths)} missions ({results[-1][1]:.0f} s)", flush=True)
    out = []
    for (d, _, _), (a, dt) in zip(jobs, results):
        if progress:
            print(f"{d.name}: {len(a.paths)} missions, EOL mission {a.eol_mission()}, {dt:.1f} s", flush=True)
        out.append(a)
    return out


def _spearman(x, y) -> float:
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 4:
        return float("nan")
    rx = np.argsort(np.argsort(x[ok]))
    ry = np.argsort(np.argsort(y[ok]))
    c = np.corrcoef(rx, ry)[0, 1]
    return float(c)


def coble_monotonicity(y, smooth: int = 5) -> float:
    """|#positive - #negative differences| / (n - 1) of the moving-median-smoothed series (Coble & Hines)."""
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    if len(y) < smooth + 2:
        return float("nan")
    k = smooth
    ys = np.array([np.median(y[max(0, i - k // 2): i + k // 2 + 1]) for i in range(len(y))])  # over missions
    d = np.diff(ys)
    return float(abs(np.sum(d > 0) - np.sum(d < 0)) / max(len(d), 1))


def auc(neg, pos) -> float:
    """Mann-Whitney AUC that a random 'advanced' value exceeds a random 'early' one (0.5 = no separation)."""
    neg, pos = np.asarray(neg, float), np.asarray(pos, float)
    neg, pos = neg[np.isfinite(neg)], pos[np.isfinite(pos)]
    if len(neg) == 0 or len(pos) == 0:
        return float("nan")
    allv = np.concatenate([neg, pos])
    r = np.argsort(np.argsort(allv)) + 1.0
    rp = r[len(neg):].sum()
    return float((rp - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def feature_study(fleet: list[ActuatorData], out_dir, early: float = 0.25, advanced: float = 0.75,
                  baseline: str = "subtract") -> dict:
    """Per feature: Spearman(feature, h) and Coble monotonicity per actuator, AUC and Fisher ratio early vs advanced.

    Features are normalised per actuator by their own first-missions
    baseline (``baseline``) so unit-to-unit offsets do not mask the trend.
    Writes ``feature_monotonicity.png``, ``feature_separability.png``,
    ``hf_vs_wear.png`` (Fig. 3), ``fault_to_failure.png`` (Fig. 8) and
    ``feature_study.json``.
    """
    from hd_prognostic.plots import _plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res = {}
    norm = {}
    for f in STUDY_FEATURES:
        ob = ObservationModel(feature=f, baseline=baseline)
        sp, mono, e_vals, a_vals = [], [], [], []
        norm[f] = []
        for a in fleet:
            y = ob.normalise(a.feature(f))
            r = a.h_true / a.h_fail
            norm[f].append((r, y))
            sp.append(_spearman(y, a.h_true))
            mono.append(coble_monotonicity(y))
            e_vals.append(y[r <= early])
            a_vals.append(y[r >= advanced])
        e, v = np.concatenate(e_vals), np.concatenate(a_vals)
        e, v = e[np.isfinite(e)], v[np.isfinite(v)]
        fisher = float((v.mean() - e.mean()) ** 2 / max(v.var() + e.var(), 1e-300)) if len(e) and len(v) else float("nan")
        res[f] = {"spearman_mean": float(np.nanmean(sp)), "spearman_min": float(np.nanmin(sp)),
                  "coble_monotonicity_mean": float(np.nanmean(mono)), "auc_early_vs_advanced": auc(e, v),
                  "fisher_ratio": fisher, "n_early": int(len(e)), "n_advanced": int(len(v)),
                  "per_actuator_spearman": dict(zip([a.actuator_id for a in fleet], sp))}
    plt = _plt()
    names = list(STUDY_FEATURES)
    # monotonicity figure
    fig, axs = plt.subplots(1, 2, figsize=(13, 4.2))
    x = np.arange(len(names))
    axs[0].bar(x - 0.2, [res[f]["spearman_mean"] for f in names], 0.4, label="Spearman(feature, wear), mean")
    axs[0].bar(x + 0.2, [res[f]["coble_monotonicity_mean"] for f in names], 0.4, label="Coble monotonicity, mean")
    axs[0].errorbar(x - 0.2, [res[f]["spearman_mean"] for f in names],
                    yerr=[[res[f]["spearman_mean"] - res[f]["spearman_min"] for f in names], [0] * len(names)],
                    fmt="none", color="k", lw=0.8)
    axs[0].set_xticks(x, names, rotation=45, ha="right", fontsize=8)
    axs[0].axhline(0, color="k", lw=0.5)
    axs[0].set_title(f"monotonicity with wear ({len(fleet)} actuators; bar min = worst actuator)", fontsize=9)
    axs[0].legend(fontsize=7)
    for r, y in norm["HF_MTW_IF"]:
        axs[1].plot(r, y, ".-", ms=2, lw=0.6, alpha=0.7)
    axs[1].set_xlabel("h / h_fail (true wear)")
    axs[1].set_ylabel("HF_MTW,IF - baseline [rad]")
    axs[1].set_title("in-flight feature vs wear, every actuator", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "feature_monotonicity.png", dpi=110)
    plt.close(fig)
    # separability figure
    ncol = 4
    nr = int(np.ceil(len(names) / ncol))
    fig, axs = plt.subplots(nr, ncol, figsize=(14, 3 * nr), squeeze=False)
    for ax, f in zip(axs.flat, names):
        e = np.concatenate([y[r <= early] for r, y in norm[f]])
        v = np.concatenate([y[r >= advanced] for r, y in norm[f]])
        e, v = e[np.isfinite(e)], v[np.isfinite(v)]
        if len(e) and len(v):
            bins = np.linspace(min(e.min(), v.min()), max(e.max(), v.max()), 40)
            ax.hist(e, bins=bins, alpha=0.6, density=True, label=f"early h<{early:g} h_fail")
            ax.hist(v, bins=bins, alpha=0.6, density=True, label=f"advanced h>{advanced:g} h_fail")
        ax.set_title(f"{f}: AUC {res[f]['auc_early_vs_advanced']:.2f}, Fisher {res[f]['fisher_ratio']:.1f}", fontsize=8)
        ax.tick_params(labelsize=7)
    axs.flat[0].legend(fontsize=6)
    for ax in list(axs.flat)[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out / "feature_separability.png", dpi=110)
    plt.close(fig)
    # Fig. 3: feature distribution per wear level
    fig, ax = plt.subplots(figsize=(7, 4))
    edges = np.linspace(0, 1.0, 7)
    r_all = np.concatenate([r for r, _ in norm["HF_MTW_IF"]])
    y_all = np.concatenate([y for _, y in norm["HF_MTW_IF"]])
    groups = [y_all[(r_all >= lo) & (r_all < hi) & np.isfinite(y_all)] for lo, hi in zip(edges[:-1], edges[1:])]
    ax.boxplot([g if len(g) else [np.nan] for g in groups], showfliers=False)
    ax.set_xticks(range(1, len(groups) + 1), [f"{lo:.2f}-{hi:.2f}" for lo, hi in zip(edges[:-1], edges[1:])])
    ax.set_xlabel("wear level h / h_fail")
    ax.set_ylabel("HF_MTW,IF - baseline [rad]")
    ax.set_title("in-flight health feature at increasing wear (all actuators)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "hf_vs_wear.png", dpi=110)
    plt.close(fig)
    # Fig. 8: fault-to-failure evolution of one actuator
    a = max(fleet, key=lambda a: len(a.paths))
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(a.mission_index, a.h_true * 1e6, "k-", label="wear h (truth)")
    ax.axhline(a.h_fail * 1e6, color="r", ls=":", label="h_fail")
    ax.set_xlabel("mission")
    ax.set_ylabel("wear depth [um]")
    ax2 = ax.twinx()
    ax2.plot(a.mission_index, a.feature("HF_MTW_IF"), ".", color="tab:orange", ms=3, label="HF_MTW,IF")
    ax2.set_ylabel("HF_MTW,IF [rad]")
    fig.legend(fontsize=7, loc="upper left")
    ax.set_title(f"fault-to-failure: {a.actuator_id}", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "fault_to_failure.png", dpi=110)
    plt.close(fig)
    (out / "feature_study.json").write_text(json.dumps(res, indent=2, default=float))
    return res


def ukf_history(a: ActuatorData, obs: ObservationModel, n_samples: int = 2000, seed: int = 0,
                max_missions: int = 2000) -> dict:
    """UKF baseline on the same model and data: median/P5/P95 RUL per mission."""
    from hd_prognostic.ukf import UnscentedKalmanFilter

    model = build_model(obs, offset_mode="state")
    t, y, expo = mission_sequence(a, obs)
    ukf = UnscentedKalmanFilter.from_prior(model, seed=seed)
    rng = np.random.default_rng(seed)
    out = {"t": [], "p5": [], "p50": [], "p95": []}
    for k in range(len(t)):
        ukf.step(expo[k], y[k])
        past = expo[1: k + 1]
        past = past[past > 0]
        fut = past if len(past) >= 3 else float(obs.degradation["W_median"])
        r = rul_distribution(model, ukf.sample(n_samples, rng), None, fut, 1.0, max_missions, rng)
        out["t"].append(float(t[k]))
        out["p5"].append(r.p5)
        out["p50"].append(r.p50)
        out["p95"].append(r.p95)
    return out


def fleet_eval(fleet: list[ActuatorData], out_dir, *, folds: int = 4, n_particles: int = 2000, seed: int = 0,
               feature: str = "HF_MTW_IF", degree: int = 2, baseline: str = "subtract",
               likelihood: str = "student_t", with_ukf: bool = True, alpha: float = 0.2, progress: bool = True,
               fuse: list[str] | None = None, kappa_lifetime: bool = False, predictive_prior: bool = False,
               pf_options: dict | None = None) -> dict:
    """k-fold held-out evaluation over actuators; writes per-actuator and aggregate metrics, figures."""
    from hd_prognostic.plots import save_alpha_lambda_grid, save_snapshot, save_state_history

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ids = [a.actuator_id for a in fleet]
    folds = max(2, min(folds, len(fleet)))
    fold_of = {aid: i % folds for i, aid in enumerate(sorted(ids))}
    per, per_ukf, hists, eols, rows, censored = [], [], [], [], [], {}
    for fi in range(folds):
        train = [a for a in fleet if fold_of[a.actuator_id] != fi]
        test = [a for a in fleet if fold_of[a.actuator_id] == fi]
        if not test:
            continue
        obs = fit_population(train, feature=feature, degree=degree, baseline=baseline, fuse=fuse,
                             kappa_lifetime=kappa_lifetime, predictive_prior=predictive_prior)
        obs.to_json(out / f"obs_model_fold{fi}.json")
        for a in test:
            eol = a.eol_mission()
            t0 = time.perf_counter()
            snaps = ()
            if np.isfinite(eol):
                n = int(eol - a.mission_index[0])
                snaps = (max(1, n // 2), max(1, int(0.85 * n)))
            hist = prognose(a, obs, n_particles=n_particles, seed=seed, likelihood=likelihood,
                            snapshots=snaps, pf_options=pf_options)
            dt = time.perf_counter() - t0
            (out / f"rul_{a.actuator_id}.json").write_text(json.dumps(hist.to_json()))
            if not np.isfinite(eol):
                censored[a.actuator_id] = "never reaches h_fail in the simulated missions"
                continue
            m = M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, eol, alpha=alpha, samples=hist.samples,
                                rul_horizon=hist.meta.get("rul_horizon"))
            m["actuator_id"] = a.actuator_id
            m["fold"] = fi
            m["seconds"] = dt
            per.append(m)
            hists.append(hist)
            eols.append(eol)
            model = build_model(obs)
            for s in hist.meta.get("snapshots", []):
                ti = int(np.searchsorted(a.mission_index, s["t"]))
                th = a.h_true[ti] if ti < len(a.h_true) and a.mission_index[ti] == s["t"] else None
                save_snapshot(out / f"pf_{a.actuator_id}_m{int(s['t'])}.png", s, model, model.h_fail, th,
                              title=f"{a.actuator_id}, mission {int(s['t'])} (EOL {int(eol)})", state_scale=1e6,
                              state_unit="um", time_unit="mission")
            save_state_history(out / f"state_{a.actuator_id}.png", hist, a.mission_index, a.h_true, 1e6, "um",
                               title=f"{a.actuator_id}: wear tracking")
            row = {"actuator_id": a.actuator_id, "method": "PF", **{k: m[k] for k in (
                "frac_in_cone_lambda_ge_0.5", "coverage_p5_p95", "cra", "ph_point", "ph_beta", "convergence",
                "mae", "pit_ks", "crps_mean")}, "t_eol": eol}
            rows.append(row)
            if with_ukf:
                u = ukf_history(a, obs, seed=seed)
                mu = M.score_history(u["t"], u["p50"], u["p5"], u["p95"], eol, alpha=alpha)
                mu["actuator_id"] = a.actuator_id
                per_ukf.append(mu)
                rows.append({"actuator_id": a.actuator_id, "method": "UKF", **{k: mu.get(k) for k in (
                    "frac_in_cone_lambda_ge_0.5", "coverage_p5_p95", "cra", "ph_point", "ph_beta", "convergence",
                    "mae")}, "t_eol": eol})
            if progress:
                print(f"{a.actuator_id} (fold {fi}): EOL {eol:.0f}, in-cone(lambda>=0.5) "
                      f"{m['frac_in_cone_lambda_ge_0.5']:.2f}, P5-P95 coverage {m['coverage_p5_p95']:.2f}, "
                      f"CRA {m['cra']:.2f}  [{dt:.1f} s]"
                      + (f"  | UKF in-cone {per_ukf[-1]['frac_in_cone_lambda_ge_0.5']:.2f} "
                         f"coverage {per_ukf[-1]['coverage_p5_p95']:.2f}" if with_ukf else ""), flush=True)
    if hists:
        save_alpha_lambda_grid(out / "alpha_lambda.png", hists, eols, alpha, unit="mission",
                               title=f"held-out actuators, PF, alpha = {alpha:g}")
    summary = {"per_actuator": per, "aggregate": M.aggregate(per), "censored": censored,
               "ukf_per_actuator": per_ukf, "ukf_aggregate": M.aggregate(per_ukf) if per_ukf else {},
               "settings": {"folds": folds, "n_particles": n_particles, "seed": seed, "feature": feature,
                            "degree": degree, "baseline": baseline, "likelihood": likelihood, "alpha": alpha,
                            "fuse": fuse, "kappa_lifetime": kappa_lifetime, "predictive_prior": predictive_prior,
                            "pf_options": pf_options}}
    (out / "eval_summary.json").write_text(json.dumps(summary, indent=2, default=float))
    if rows:
        keys = list(rows[0].keys())
        with open(out / "eval_per_actuator.csv", "w") as f:
            f.write(",".join(keys) + "\n")
            for r in rows:
                f.write(",".join(str(r.get(k, "")) for k in keys) + "\n")
    return summary
