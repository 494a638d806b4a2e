"""Prognostic performance metrics (Saxena, Celaya, Saha, Saha & Goebel 2008-2010).

Conventions (PHYSICS.md section 6.2): ``t`` are prediction times, ``t_eol``
the true end of life, ``t_p`` the first prediction time, ``r_true(t) =
t_eol - t``, predictions ``r_hat`` (the median unless stated). Metrics are
computed per unit and averaged across units by the caller; only predictions
with ``t_p <= t < t_eol`` count. alpha, lambda and beta are explicit
arguments and are echoed in :func:`score_history`'s output.
"""

from __future__ import annotations

import numpy as np


def _arr(a) -> np.ndarray:
    return np.atleast_1d(np.asarray(a, dtype=float))


def true_rul(t, t_eol: float) -> np.ndarray:
    return float(t_eol) - _arr(t)


def in_alpha_cone(r_hat, r_true, alpha: float = 0.2) -> np.ndarray:
    """(1 - alpha) r* <= r_hat <= (1 + alpha) r* per prediction (the shrinking alpha-lambda cone)."""
    r_hat, r_true = _arr(r_hat), _arr(r_true)
    return ((1 - alpha) * r_true <= r_hat) & (r_hat <= (1 + alpha) * r_true)


def alpha_lambda(t, r_hat, t_eol: float, t_p: float | None = None, alpha: float = 0.2,
                 lambdas=(0.25, 0.5, 0.75)) -> dict[float, bool]:
    """alpha-lambda accuracy: pass/fail at t_lambda = t_p + lambda (t_eol - t_p).

    The prediction used at t_lambda is the latest one made at or before it
    (predictions are piecewise constant between updates). Returns lambda -> pass.
    """
    t, r_hat = _arr(t), _arr(r_hat)
    t_p = float(t[0]) if t_p is None else float(t_p)
    out: dict[float, bool] = {}
    for lam in lambdas:
        tl = t_p + lam * (t_eol - t_p)
        i = np.searchsorted(t, tl, side="right") - 1
        if i < 0:
            out[float(lam)] = False
            continue
        rt = t_eol - tl
        # prediction made at t[i], aged to t_lambda
        rh = r_hat[i] - (tl - t[i])
        out[float(lam)] = bool(in_alpha_cone(rh, rt, alpha)[0])
    return out


def fraction_in_cone(t, r_hat, t_eol: float, t_p: float | None = None, alpha: float = 0.2,
                     lambda_min: float = 0.5) -> float:
    """Fraction of the predictions with lambda >= ``lambda_min`` (and t < t_eol) inside the alpha cone."""
    t, r_hat = _arr(t), _arr(r_hat)
    t_p = float(t[0]) if t_p is None else float(t_p)
    lam = (t - t_p) / (t_eol - t_p)
    sel = (lam >= lambda_min) & (t < t_eol)
    if not sel.any():
        return float("nan")
    return float(np.mean(in_alpha_cone(r_hat[sel], t_eol - t[sel], alpha)))


def relative_accuracy(r_hat, r_true) -> np.ndarray:
    """RA = 1 - |r* - r_hat| / r*."""
    r_hat, r_true = _arr(r_hat), _arr(r_true)
    return 1.0 - np.abs(r_true - r_hat) / r_true


def cumulative_relative_accuracy(t, r_hat, t_eol: float, weights=None) -> float:
    """CRA: weighted mean of RA over the prediction times with t < t_eol (uniform weights by default)."""
    t, r_hat = _arr(t), _arr(r_hat)
    sel = t < t_eol
    if not sel.any():
        return float("nan")
    ra = relative_accuracy(r_hat[sel], t_eol - t[sel])
    w = np.ones(sel.sum()) if weights is None else _arr(weights)[sel]
    return float(np.sum(w * ra) / np.sum(w))


def convergence(t, metric_values, t_p: float | None = None) -> float:
    """Saxena's convergence: distance from (t_p, 0) to the centroid of the area under M(t).

    ``metric_values`` is a non-negative error measure per prediction time
    (e.g. |r* - r_hat|); the area is the piecewise-constant one between
    consecutive prediction times. Smaller is better (fast convergence).
    """
    t, m = _arr(t), np.abs(_arr(metric_values))
    if len(t) < 2:
        return float("nan")
    t_p = float(t[0]) if t_p is None else float(t_p)
    dt = np.diff(t)
    mi = m[:-1]
    area = np.sum(dt * mi)
    if area <= 0:
        return 0.0
    xc = np.sum((t[1:] ** 2 - t[:-1] ** 2) * mi) / (2 * area)
    yc = np.sum(dt * mi**2) / (2 * area)
    return float(np.hypot(xc - t_p, yc))


def prognostic_horizon(t, t_eol: float, r_hat=None, samples=None, weights=None, alpha: float = 0.05,
                       beta: float = 0.5) -> float:
    """PH = t_eol - t_i, t_i the first time after which every prediction stays in r*(t) +- alpha t_eol.

    Point form (``r_hat``) or probabilistic form (``samples``: list of RUL
    sample arrays, optional ``weights``): a prediction is inside when at
    least a fraction ``beta`` of its probability mass is in the band. 0 when
    the last prediction is outside.
    """
    t = _arr(t)
    sel = t < t_eol
    t = t[sel]
    rt = t_eol - t
    lo, hi = rt - alpha * t_eol, rt + alpha * t_eol
    if samples is not None:
        samples = [s for s, k in zip(samples, sel) if k]
        ws = [None] * len(samples) if weights is None else [w for w, k in zip(weights, sel) if k]
        inside = np.array([_mass_in(s, w, a, b) >= beta for s, w, a, b in zip(samples, ws, lo, hi)])
    elif r_hat is not None:
        rh = _arr(r_hat)[sel]
        inside = (rh >= lo) & (rh <= hi)
    else:
        raise ValueError("prognostic_horizon needs r_hat or samples")
    if len(inside) == 0 or not inside[-1]:
        return 0.0
    out = np.flatnonzero(~inside)
    i = 0 if len(out) == 0 else out[-1] + 1
    return float(t_eol - t[i])


def _mass_in(s, w, a, b) -> float:
    s = np.asarray(s, float)
    w = np.full(len(s), 1.0 / len(s)) if w is None else np.asarray(w, float) / np.sum(w)
    return float(np.sum(w[(s >= a) & (s <= b)]))


def coverage(lo, hi, r_true) -> float:
    """Fraction of the true RULs inside [lo, hi] (e.g. the P5-P95 interval: nominal 90 %)."""
    lo, hi, r = _arr(lo), _arr(hi), _arr(r_true)
    return float(np.mean((r >= lo) & (r <= hi)))


def pit(samples, r_true, weights=None) -> float:
    """Probability integral transform: predicted CDF at the true RUL (uniform when calibrated).

    Ties (discrete RUL steps) are split randomisation-free at the midpoint.
    """
    s = np.asarray(samples, float)
    w = np.full(len(s), 1.0 / len(s)) if weights is None else np.asarray(weights, float) / np.sum(weights)
    return float(np.sum(w[s < r_true]) + 0.5 * np.sum(w[s == r_true]))


def calibration_error(pit_values, n_bins: int = 10) -> float:
    """Max |empirical CDF - uniform CDF| of PIT values (Kolmogorov-Smirnov distance; 0 = calibrated)."""
    p = np.sort(_arr(pit_values))
    n = len(p)
    if n == 0:
        return float("nan")
    ecdf_hi = np.arange(1, n + 1) / n
    ecdf_lo = np.arange(0, n) / n
    return float(max(np.max(ecdf_hi - p), np.max(p - ecdf_lo)))


def crps(samples, y: float, weights=None) -> float:
    """Continuous ranked probability score of a (weighted) sample distribution at outcome ``y``.

    CRPS = E|X - y| - 0.5 E|X - X'|, exact for the empirical distribution;
    same unit as the RUL, lower is better; equals |x - y| for a point forecast.
    """
    s = np.asarray(samples, float)
    w = np.full(len(s), 1.0 / len(s)) if weights is None else np.asarray(weights, float) / np.sum(weights)
    o = np.argsort(s)
    s, w = s[o], w[o]
    c = np.cumsum(w)
    e1 = np.sum(w * np.abs(s - y))
    e2 = 2.0 * np.sum(w * s * (c + (c - w) - 1.0))
    return float(e1 - 0.5 * e2)


def score_history(t, p50, p5, p95, t_eol: float, *, t_p: float | None = None, alpha: float = 0.2,
                  lambdas=(0.25, 0.5, 0.75), alpha_ph: float = 0.05, beta: float = 0.5,
                  samples=None, weights=None) -> dict:
    """All metrics for one unit's RUL history (only predictions with t < t_eol count).

    ``samples``/``weights`` (optional, one array per prediction) enable the
    probabilistic prognostic horizon, PIT and CRPS; otherwise CRPS/PIT are
    omitted and PH uses the median.
    """
    t, p50, p5, p95 = _arr(t), _arr(p50), _arr(p5), _arr(p95)
    # "no failure within the forecast horizon" (inf) is scored as a RUL of 2 t_eol: badly wrong, but finite
    cap = 2.0 * abs(float(t_eol)) + 1.0
    p50, p5 = np.minimum(p50, cap), np.minimum(p5, cap)
    sel = t < t_eol
    if t_p is not None:
        sel &= t >= t_p
    if not sel.any():
        return {"n_predictions": 0, "t_eol": float(t_eol)}
    idx = np.flatnonzero(sel)
    t, p50, p5, p95 = t[sel], p50[sel], p5[sel], p95[sel]
    if samples is not None:
        samples = [samples[i] for i in idx]
        weights = None if weights is None else [weights[i] for i in idx]
    t_p = float(t[0]) if t_p is None else float(t_p)
    rt = t_eol - t
    err = np.abs(rt - p50)
    out = {
        "t_eol": float(t_eol), "t_p": t_p, "n_predictions": int(len(t)),
        "alpha": alpha, "lambdas": list(lambdas), "alpha_ph": alpha_ph, "beta": beta,
        "alpha_lambda": {str(k): v for k, v in alpha_lambda(t, p50, t_eol, t_p, alpha, lambdas).items()},
        "frac_in_cone_lambda_ge_0.5": fraction_in_cone(t, p50, t_eol, t_p, alpha, 0.5),
        "frac_in_cone_all": float(np.mean(in_alpha_cone(p50, rt, alpha))),
        "relative_accuracy_lambda_0.5": float(relative_accuracy(
            p50[min(np.searchsorted(t, t_p + 0.5 * (t_eol - t_p)), len(t) - 1)],
            t_eol - t[min(np.searchsorted(t, t_p + 0.5 * (t_eol - t_p)), len(t) - 1)])[0]),
        "cra": cumulative_relative_accuracy(t, p50, t_eol),
        "convergence": convergence(t, err, t_p),
        "prognostic_horizon": prognostic_horizon(t, t_eol, r_hat=p50, samples=samples, weights=weights,
                                                 alpha=alpha_ph, beta=beta),
        "coverage_p5_p95": coverage(p5, p95, rt),
        "mae": float(np.mean(err)),
    }
    if samples is not None:
        ws = [None] * len(samples) if weights is None else weights
        pits = [pit(s, r, w) for s, r, w in zip(samples, rt, ws)]
        out["pit"] = pits
        out["pit_ks"] = calibration_error(pits)
        out["crps_mean"] = float(np.mean([crps(np.where(np.isfinite(s), s, 10 * t_eol), r, w)
                                          for s, r, w in zip(samples, rt, ws)]))
    return out


def aggregate(per_unit: list[dict]) -> dict:
    """Mean across units of the scalar metrics (per-unit first, then average)."""
    keys = ["frac_in_cone_lambda_ge_0.5", "frac_in_cone_all", "relative_accuracy_lambda_0.5", "cra",
            "convergence", "prognostic_horizon", "coverage_p5_p95", "mae", "pit_ks", "crps_mean"]
    out = {}
    for k in keys:
        v = [u[k] for u in per_unit if k in u and u[k] is not None and np.isfinite(u[k])]
        if v:
            out[k] = float(np.mean(v))
    lam = {}
    for u in per_unit:
        for k, v in u.get("alpha_lambda", {}).items():
            lam.setdefault(k, []).append(v)
    out["alpha_lambda_pass_rate"] = {k: float(np.mean(v)) for k, v in lam.items()}
    out["n_units"] = len(per_unit)
    return out
