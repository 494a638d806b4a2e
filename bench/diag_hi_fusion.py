"""Does a health indicator fused from several onboard features rise less scattered at failure? (issue 12)

Feasibility check for the classic data-fusion HI (Liu, Gebraeel & Shi 2013: the linear combination of features whose
value at failure varies least across the failed units, relative to its rise). The life model's in-cone gap was traced
to HF_MTW_IF's per-unit gain (its rise at failure scatters more than the failure wear itself, README of
hd_prognostic); a fused HI helps only if its rise at failure scatters less.

Per unit, from operator records only (contract-topic features per mission and the failure mission of the events):

* each feature's *rise at failure*: a straight line through its last ``--last`` missions before the failure,
  evaluated at the failure mission, minus a line through its first ``--early`` missions at the first mission (the
  operator's early level; the lines remove the wear growth over the averaged missions, which is larger in short
  lives);
* its per-mission noise: the robust sd of first differences / sqrt 2.

Per fleet and per feature, the scatter of the rise over the failed units (sd of log rise; the leave-one-unit-out
version ``log(r_i / mean of the others' r)`` is printed, it also counts the fold-to-fold change of the mean) and the
noise-to-rise ratio (median per-mission noise sd over the median rise). The fused HI is ``sum_f w_f (y_f -
early_f) / mu_f`` with ``mu_f`` the training units' mean rise of feature f (so every candidate's mean rise is 1) and
``w >= 0`` (a non-negative combination of rising features stays rising), ``sum w = 1``, minimising, over the
TRAINING units of each fold only (the held-out unit's rise is then scored with those weights):

* ``fused``: ``w' S_R w`` (S_R: the covariance of the standardised rises across training units; Liu et al.);
* ``fused+noise``: ``w' (S_R + S_N) w`` (S_N: the per-mission noise covariance, pooled over the training units: the
  model observes single missions, so the fused HI must not trade scatter for noise).

With ``fleet_truth.json`` present (diagnosis only, never a fit input) it also prints the failure wear's scatter
(sd of log ``h_fail``) and each HI's *noise-free* rise (a quadratic of the HI in the true wear, evaluated at
``h_fail`` minus at the first mission's wear: the column of diag_prognostics_gap.py for HF_MTW_IF); for the fused
rows that column is what fusion could give at most: weights fitted leave-one-unit-out on the noise-free rises.

    python bench/diag_hi_fusion.py --fleet dev=DIR[:EVENTS.csv] --fleet hr31=DIR ... --cache CACHE_ROOT
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

CANDIDATES = ("HF_MTW_IF", "ke_1x", "ke_4x", "lost_motion", "hysteresis", "te_rms", "ke_indicator", "cs_coulomb")


def unit_rises(a, feats, fail_mission: float, early: int = 10, last: int = 10):
    """(rise per feature, per-mission noise sd per feature, early level, aligned feature matrix) of one unit."""
    mi = a.mission_index.astype(float)
    Y = np.column_stack([a.feature(f) for f in feats])
    keep = mi < fail_mission
    Y, mi = Y[keep], mi[keep]
    e0 = _line_at(mi[:early], Y[:early], mi[0])
    e1 = _line_at(mi[-last:], Y[-last:], fail_mission)
    d = np.diff(Y, axis=0)
    d = d[np.all(np.isfinite(d), axis=1)]
    return e1 - e0, d, e0, Y, mi


def _line_at(x, Y, x0):
    """Per column, a straight line through the finite (x, y) evaluated at x0 (a level with its trend removed)."""
    out = np.full(Y.shape[1], np.nan)
    for j in range(Y.shape[1]):
        ok = np.isfinite(Y[:, j])
        if ok.sum() >= 3:
            c = np.polyfit(x[ok] - x0, Y[ok, j], 1)
            out[j] = c[1]
    return out


def fuse_weights(R: np.ndarray, D: np.ndarray | None = None) -> np.ndarray:
    """Non-negative weights, sum 1, minimising w' (cov(R) + cov_noise) w for rises R standardised to mean 1.

    ``R``: (units, features) standardised rises of the training units; ``D``: first differences of the standardised
    features pooled over the training units (noise covariance = cov(D) / 2), or None for the rise scatter alone.
    """
    from scipy.optimize import minimize

    S = np.cov(R, rowvar=False, ddof=1)
    if D is not None and len(D) > 2:
        S = S + np.cov(D, rowvar=False) / 2.0
    S = np.atleast_2d(S)
    n = S.shape[0]
    w0 = np.full(n, 1.0 / n)
    res = minimize(lambda w: w @ S @ w, w0, jac=lambda w: 2 * S @ w, method="SLSQP", bounds=[(0, 1)] * n,
                   constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0}], options={"maxiter": 500, "ftol": 1e-14})
    w = np.clip(res.x, 0, None)
    return w / w.sum()


def fleet_table(acts, fail: dict, feats, early: int, last: int, truth: dict | None):
    ids = [a.actuator_id for a in acts if a.actuator_id in fail]
    A = {a.actuator_id: a for a in acts}
    rises, diffs, levels, series = {}, {}, {}, {}
    for u in ids:
        r, d, e0, Y, mi = unit_rises(A[u], feats, fail[u], early, last)
        rises[u], diffs[u], levels[u], series[u] = r, d, e0, (Y, mi)
    R = np.array([rises[u] for u in ids])  # (units, features)
    rows = {}
    # single features: orientation from the fleet (all but one unit): sign of the others' mean rise
    for j, f in enumerate(feats):
        loo, noise = [], []
        for i, u in enumerate(ids):
            m = np.mean(np.delete(R[:, j], i))
            loo.append(R[i, j] / m)
            noise.append(1.4826 * np.median(np.abs(diffs[u][:, j] - np.median(diffs[u][:, j]))) / np.sqrt(2))
        loo = np.array(loo)
        rows[f] = dict(loo=loo, sd_log=_sdlog(R[:, j] * np.sign(np.mean(R[:, j]))),
                       sd_log_loo=_sdlog(loo), nsr=float(np.median(noise) / abs(np.median(R[:, j]))))
    # fused, leave-one-unit-out: weights from the training units only
    for name, with_noise in (("fused", False), ("fused+noise", True)):
        loo, W, nsr = [], [], []
        for i, u in enumerate(ids):
            tr = [v for k, v in enumerate(ids) if k != i]
            mu = np.mean([rises[v] for v in tr], axis=0)
            ok = mu > 0  # only features that rise on the training units (a fused HI that must rise)
            if not ok.any():
                raise ValueError("no candidate feature rises on the training units")
            Rs = np.array([rises[v][ok] / mu[ok] for v in tr])
            D = np.vstack([diffs[v][:, ok] / mu[ok] for v in tr]) if with_noise else None
            w_ok = fuse_weights(Rs, D)
            w = np.zeros(len(feats))
            w[ok] = w_ok
            W.append(w)
            loo.append(float(w[ok] @ (rises[u][ok] / mu[ok])))  # training mean rise of the fused HI is 1
            du = diffs[u][:, ok] / mu[ok] @ w_ok
            nsr.append(1.4826 * np.median(np.abs(du - np.median(du))) / np.sqrt(2))
        loo = np.array(loo)
        rows[name] = dict(loo=loo, sd_log=float("nan"), sd_log_loo=_sdlog(loo), nsr=float(np.median(nsr) / 1.0),
                          weights=np.mean(W, axis=0), weights_sd=np.std(W, axis=0))
    info = dict(units=ids)
    if truth is not None:
        T = {a["actuator_id"]: a for a in truth["actuators"]}
        hf = np.array([float(T[u]["params"]["h_fail"]) for u in ids])
        info["sd_log_h_fail"] = _sdlog(hf)
        # noise-free rise per feature: quadratic of the feature in the true wear at h_fail minus at the start
        nf, NF = {}, []
        for j, f in enumerate(feats):
            r = []
            for u, h_f in zip(ids, hf):
                Y, mi = series[u]
                h = _true_h(T[u], mi)
                ok = np.isfinite(Y[:, j]) & np.isfinite(h)
                c = np.polyfit(h[ok], Y[ok, j], 2)
                r.append(np.polyval(c, h_f) - np.polyval(c, h[ok][0]))
            nf[f] = _sdlog(np.array(r) * np.sign(np.mean(r)))
            NF.append(r)
        NF = np.array(NF).T  # (units, features)
        # the most fusion could give: weights fitted leave-one-unit-out on the NOISE-FREE rises (truth-informed)
        loo = []
        for i in range(len(ids)):
            tr = np.delete(NF, i, axis=0)
            mu = tr.mean(axis=0)
            ok = mu > 0
            w = fuse_weights(tr[:, ok] / mu[ok])
            loo.append(float(w @ (NF[i, ok] / mu[ok])))
        nf["fused"] = nf["fused+noise"] = _sdlog(loo)
        # do the features' per-unit gains move together? correlation of log noise-free rise with HF_MTW_IF's
        if "HF_MTW_IF" in feats:
            k = feats.index("HF_MTW_IF")
            info["corr_log_rise_with_HF_MTW_IF"] = {
                f: float(np.corrcoef(np.log(np.abs(NF[:, k])), np.log(np.abs(NF[:, j])))[0, 1])
                for j, f in enumerate(feats) if j != k}
        info["sd_log_noise_free"] = nf
    return rows, info


def _true_h(t: dict, mi: np.ndarray) -> np.ndarray:
    m = {int(x["mission_index"]): float(x["h"]) for x in t["missions"]}
    return np.array([m.get(int(k), np.nan) for k in mi])


def _sdlog(x) -> float:
    x = np.asarray(x, float)
    if np.any(x <= 0):
        return float("nan")  # some unit's rise has the wrong sign: no scatter of a log
    return float(np.std(np.log(x), ddof=1))


def _failures(fleet_dir: Path, events: str | None) -> dict:
    if events:
        from hd_prognostic.lifemodel import read_events

        return {u: e.failure for u, e in read_events(events).items() if e.failure is not None}
    # the failure mission as an operator records it (only eol_mission is read from the truth file)
    t = json.loads((fleet_dir / "fleet_truth.json").read_text())
    return {a["actuator_id"]: float(a["eol_mission"]) for a in t["actuators"] if a.get("eol_mission") is not None}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="diag_hi_fusion", description=__doc__.split("\n")[0])
    ap.add_argument("--fleet", action="append", required=True, metavar="NAME=DIR[:EVENTS.csv]")
    ap.add_argument("--cache", default=None, help="feature cache root (evaluate.load_fleet's, NAME/ under it)")
    ap.add_argument("--features", default=",".join(CANDIDATES))
    ap.add_argument("--early", type=int, default=10, help="missions of the early level")
    ap.add_argument("--last", type=int, default=10, help="missions before the failure fitted for its level")
    ap.add_argument("--out", default=None, help="JSON of the results")
    args = ap.parse_args(argv)
    from hd_prognostic.evaluate import load_fleet

    feats = [f.strip() for f in args.features.split(",") if f.strip()]
    out = {}
    for spec in args.fleet:
        name, _, rest = spec.partition("=")
        fdir, _, ev = rest.partition(":")
        fdir = Path(fdir)
        acts = load_fleet(fdir, cache_dir=(Path(args.cache) / name) if args.cache else None, progress=False)
        tp = fdir / "fleet_truth.json"
        truth = json.loads(tp.read_text()) if tp.exists() else None
        rows, info = fleet_table(acts, _failures(fdir, ev or None), feats, args.early, args.last, truth)
        print(f"\n== {name}: {len(info['units'])} failed units"
              + (f", sd log h_fail (truth) {info['sd_log_h_fail']:.3f}" if "sd_log_h_fail" in info else ""))
        print(f"{'HI':<14}{'sd log rise':>12}{'LOO sd log':>12}{'noise/rise':>12}{'noise-free':>12}  LOO ratios")
        for k, r in rows.items():
            nf = info.get("sd_log_noise_free", {}).get(k, float("nan"))
            print(f"{k:<14}{r['sd_log']:>12.3f}{r['sd_log_loo']:>12.3f}{r['nsr']:>12.3f}{nf:>12.3f}  "
                  + " ".join(f"{x:.2f}" for x in r["loo"]))
            if "weights" in r:
                print(" " * 14 + "mean weights: " + ", ".join(
                    f"{f} {w:.2f}+-{s:.2f}" for f, w, s in zip(feats, r["weights"], r["weights_sd"]) if w > 0.005))
        if "corr_log_rise_with_HF_MTW_IF" in info:
            print("corr of log noise-free rise with HF_MTW_IF's: " + ", ".join(
                f"{f} {c:+.2f}" for f, c in info["corr_log_rise_with_HF_MTW_IF"].items()))
        out[name] = dict(info, rows={k: {kk: (vv.tolist() if isinstance(vv, np.ndarray) else vv)
                                         for kk, vv in r.items()} for k, r in rows.items()})
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
