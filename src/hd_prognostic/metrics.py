"""Prognostic performance metrics (Saxena, Celaya, Saha, Saha & Goebel 2008-2010), PIT and CRPS.

Conventions (PHYSICS.md section 6.2): ``t`` are prediction times, ``t_eol``
the true end of life, ``t_p`` the first prediction time, ``r*(t) = t_eol -
t`` the true RUL, predictions ``r_hat`` (the median, P50, unless stated).
Metrics are computed per unit and averaged across units by the caller; only
predictions with ``t_p <= t < t_eol`` count. alpha, lambda and beta are
explicit arguments and are echoed in :func:`score_history`'s output.

Every metric is named by what it computes; the table of formulas and how each
differs from progpy's and from Saxena et al.'s (2010) definition is in
``src/hd_prognostic/README.md``. The rules that are choices:

* **Infinite predictions** ("no failure within the forecast horizon H") are
  the only values replaced, by one cap for every quantity (P5, P50, P95 and
  samples): ``inf_cap = max(H, r*(t_p))``, the smallest RUL such a forecast
  asserts, never below the longest true RUL scored. ``H`` is the forecast
  horizon (``rul_horizon``; ``RULHistory.meta["rul_horizon"]``), or, when
  unknown, the largest finite RUL value in the scored history. Finite values
  are never clipped, so every finite value is <= the cap (ranking kept).
* **The prediction at t_lambda** (alpha-lambda point and beta forms, RA at
  lambda): ``convention="hdphm"`` (default) uses the latest prediction made
  at or before ``t_lambda``, aged to it (``r_hat - (t_lambda - t_i)``, samples
  likewise), against ``r*(t_lambda)`` -- what an operator holds at
  ``t_lambda``. ``convention="progpy"`` uses progpy's rule: the first
  prediction at or after ``t_lambda``, unaged, against ``r*`` at its own time.
* **Cones and bands** are closed (``<=``, Saxena's) in ``"hdphm"`` and open
  (``<``, progpy's ``percentage_in_bounds``) in ``"progpy"``.
* **RA / CRA** use the median in ``"hdphm"`` (``1 - |r* - r_hat| / r*``,
  Saxena's); in ``"progpy"`` they use the mean of the ToE samples ``t + s``
  relative to the true ToE, ``1 - |t_eol - mean(t + s)| / t_eol`` (progpy's
  ``UncertainData.relative_accuracy`` on a ToE profile; the P50 when there are
  no samples).
* **PH** has two forms: ``ph_*`` first entry (Saxena's and progpy's: the
  first prediction that meets the criterion) and ``ph_*_sustained`` (every
  later prediction meets it too). Never met: 0 in ``"hdphm"``, None (progpy's
  value) in ``"progpy"``.
"""

from __future__ import annotations

import numpy as np

CONVENTIONS = ("hdphm", "progpy")
RULES = {
    "hdphm": {
        "t_lambda_rule": "latest prediction at or before t_lambda, aged to t_lambda, against r*(t_lambda)",
        "cone": "closed",
        "ra": "1 - |r* - P50| / r* (median)",
    },
    "progpy": {
        "t_lambda_rule": "first prediction at or after t_lambda, unaged, against r* at its own time (progpy)",
        "cone": "open",
        "ra": "1 - |t_eol - mean(t + samples)| / t_eol (mean ToE relative to the true ToE, progpy)",
    },
}


def _arr(a) -> np.ndarray:
    return np.atleast_1d(np.asarray(a, dtype=float))


def _check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise ValueError(f"unknown metrics convention {convention!r}: use one of {CONVENTIONS}")


def _norm_w(n: int, w) -> np.ndarray:
    return np.full(n, 1.0 / n) if w is None else np.asarray(w, float) / np.sum(w)


def true_rul(t, t_eol: float) -> np.ndarray:
    return float(t_eol) - _arr(t)


def in_alpha_cone(r_hat, r_true, alpha: float = 0.2, closed: bool = True) -> np.ndarray:
    """(1 - alpha) r* <= r_hat <= (1 + alpha) r* per prediction (closed; ``closed=False``: strict, progpy's)."""
    r_hat, r_true = _arr(r_hat), _arr(r_true)
    if closed:
        return ((1 - alpha) * r_true <= r_hat) & (r_hat <= (1 + alpha) * r_true)
    return ((1 - alpha) * r_true < r_hat) & (r_hat < (1 + alpha) * r_true)


def prediction_at(t, t_lambda: float, convention: str = "hdphm") -> tuple[int | None, float]:
    """Index of the prediction used at ``t_lambda`` and its age (see the module docstring; None if none)."""
    _check_convention(convention)
    t = _arr(t)
    if convention == "hdphm":
        i = int(np.searchsorted(t, t_lambda, side="right")) - 1
        return (None, 0.0) if i < 0 else (i, float(t_lambda - t[i]))
    i = int(np.searchsorted(t, t_lambda, side="left"))
    return (None, 0.0) if i >= len(t) else (i, 0.0)


def _progpy_toe_in(t_i: float, s, w, t_eol: float, alpha: float) -> float:
    """Mass of ToE = t_i + s strictly inside progpy's alpha bounds t_eol -+ alpha (t_eol - t_i)."""
    toe = t_i + np.asarray(s, float)
    lo, hi = t_eol - alpha * (t_eol - t_i), t_eol + alpha * (t_eol - t_i)
    return float(np.sum(_norm_w(len(toe), w)[(toe > lo) & (toe < hi)]))


def alpha_lambda(t, r_hat, t_eol: float, t_p: float | None = None, alpha: float = 0.2,
                 lambdas=(0.25, 0.5, 0.75), *, samples=None, weights=None, beta: float = 0.5,
                 convention: str = "hdphm") -> dict[float, bool | None]:
    """alpha-lambda accuracy at t_lambda = t_p + lambda (t_eol - t_p): lambda -> pass (None: no prediction).

    Point form (``r_hat``, the median) or beta form (``samples``: pass when at
    least a fraction ``beta`` of the probability mass is inside the cone).
    Which prediction is used, and whether the cone is closed, follows
    ``convention`` (module docstring).
    """
    _check_convention(convention)
    t = _arr(t)
    t_p = float(t[0]) if t_p is None else float(t_p)
    out: dict[float, bool | None] = {}
    for lam in lambdas:
        tl = t_p + lam * (t_eol - t_p)
        i, age = prediction_at(t, tl, convention)
        if i is None:
            out[float(lam)] = None
            continue
        w = None if weights is None else weights[i]
        if convention == "hdphm":
            rt = t_eol - tl
            if samples is None:
                out[float(lam)] = bool(in_alpha_cone(_arr(r_hat)[i] - age, rt, alpha)[0])
            else:
                inside = in_alpha_cone(np.asarray(samples[i], float) - age, rt, alpha)
                out[float(lam)] = bool(np.sum(_norm_w(len(inside), w)[inside]) >= beta)
        else:
            s = [_arr(r_hat)[i]] if samples is None else samples[i]
            out[float(lam)] = bool(_progpy_toe_in(t[i], s, w, t_eol, alpha) >= (1.0 if samples is None else beta))
    return out


def fraction_in_cone(t, r_hat, t_eol: float, t_p: float | None = None, alpha: float = 0.2,
                     lambda_min: float = 0.5) -> float:
    """Fraction of the predictions with lambda >= ``lambda_min`` (and t < t_eol) inside the closed alpha cone,
    each at its own time."""
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


def relative_accuracy_at(t, r_hat, t_eol: float, lam: float, t_p: float | None = None, *, samples=None,
                         weights=None, convention: str = "hdphm") -> float:
    """RA at t_lambda, with the same prediction as :func:`alpha_lambda` (NaN if there is none).

    ``"hdphm"``: Saxena's RA of the aged median against r*(t_lambda);
    ``"progpy"``: progpy's RA of the mean ToE (samples, else the median) against t_eol.
    """
    t = _arr(t)
    t_p = float(t[0]) if t_p is None else float(t_p)
    tl = t_p + lam * (t_eol - t_p)
    i, age = prediction_at(t, tl, convention)
    if i is None:
        return float("nan")
    if convention == "hdphm":
        return float(relative_accuracy(_arr(r_hat)[i] - age, t_eol - tl)[0])
    w = None if weights is None else weights[i]
    return _progpy_ra(t[i], [_arr(r_hat)[i]] if samples is None else samples[i], w, t_eol)


def _progpy_ra(t_i: float, s, w, t_eol: float) -> float:
    toe = t_i + np.asarray(s, float)
    m = np.mean(toe) if w is None else float(np.sum(_norm_w(len(toe), w) * toe))
    return float(1 - abs(t_eol - m) / t_eol)


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
                       beta: float = 0.5, *, form: str = "first", convention: str = "hdphm") -> float | None:
    """PH = t_eol - t_i for predictions inside the band r*(t) -+ alpha t_eol.

    ``form="first"``: t_i is the first prediction inside (Saxena's and
    progpy's definition); ``form="sustained"``: the first after which every
    prediction stays inside. Point form (``r_hat``) or beta form (``samples``,
    optional ``weights``: inside when at least a fraction ``beta`` of the mass
    is in the band). Closed band, never met -> 0 (``"hdphm"``); open band,
    never met -> None (``"progpy"``, with its arithmetic: ToE = t + s, TtE =
    ToE - t).
    """
    _check_convention(convention)
    if form not in ("first", "sustained"):
        raise ValueError(f"prognostic_horizon form must be 'first' or 'sustained', not {form!r}")
    t = _arr(t)
    sel = t < t_eol
    t = t[sel]
    rt = t_eol - t
    lo, hi = rt - alpha * t_eol, rt + alpha * t_eol
    if samples is not None:
        samples = [s for s, k in zip(samples, sel) if k]
        ws = [None] * len(samples) if weights is None else [w for w, k in zip(weights, sel) if k]
        b = beta
    elif r_hat is not None:
        samples = [[v] for v in _arr(r_hat)[sel]]
        ws = [None] * len(samples)
        b = 1.0
    else:
        raise ValueError("prognostic_horizon needs r_hat or samples")
    if convention == "hdphm":
        inside = np.array([_mass_in(s, w, a, c) >= b for s, w, a, c in zip(samples, ws, lo, hi)], bool)
    else:
        inside = np.array([_mass_in_open((ti + np.asarray(s, float)) - ti, w, (t_eol - ti) - alpha * t_eol,
                                         (t_eol - ti) + alpha * t_eol) >= b
                           for ti, s, w in zip(t, samples, ws)], bool)
    never = 0.0 if convention == "hdphm" else None
    if form == "first":
        hit = np.flatnonzero(inside)
        return never if len(hit) == 0 else float(t_eol - t[hit[0]])
    if len(inside) == 0 or not inside[-1]:
        return never
    out = np.flatnonzero(~inside)
    i = 0 if len(out) == 0 else out[-1] + 1
    return float(t_eol - t[i])


def _mass_in(s, w, a, b) -> float:
    s = np.asarray(s, float)
    return float(np.sum(_norm_w(len(s), w)[(s >= a) & (s <= b)]))


def _mass_in_open(s, w, a, b) -> float:
    s = np.asarray(s, float)
    return float(np.sum(_norm_w(len(s), w)[(s > a) & (s < b)]))


def coverage(lo, hi, r_true) -> float:
    """Fraction of the true RULs inside [lo, hi] (e.g. the P5-P95 interval: nominal 90 %)."""
    lo, hi, r = _arr(lo), _arr(hi), _arr(r_true)
    return float(np.mean((r >= lo) & (r <= hi)))


def coverage_interval(per_unit, level: float = 0.95, n_boot: int = 4000, seed: int = 0,
                      target: tuple[float, float] = (0.85, 0.95)) -> dict:
    """Uncertainty of a fleet's P5-P95 coverage (the mean of its units' coverages) from its units alone.

    A unit's predictions are one trajectory (strongly correlated), so the unit is the sampling unit:
    ``boot``: percentile interval of the mean over ``n_boot`` unit-level bootstrap resamples (seeded; it
    sees only the between-unit variation present, and is degenerate, e.g. [1, 1], when every unit has the
    same coverage; with 6-8 units it is known to be somewhat narrow); ``wilson``: the Wilson score interval
    of the mean with one effective Bernoulli trial per unit (binomial by unit, the conservative bound when
    the within-unit correlation is near 1). ``se``: sd / sqrt(n) of the unit coverages. ``consistent_*``:
    whether that interval meets the target band ``target``. NaN unit values are dropped."""
    c = _arr(per_unit)
    c = c[np.isfinite(c)]
    n = len(c)
    out = {"n_units": n, "coverage": float(np.mean(c)) if n else float("nan")}
    if n == 0:
        return out
    a = 0.5 * (1.0 - level)
    rng = np.random.default_rng(seed)
    means = c[rng.integers(0, n, (n_boot, n))].mean(1)
    lo, hi = (float(v) for v in np.quantile(means, [a, 1.0 - a]))
    from statistics import NormalDist

    zq = NormalDist().inv_cdf(1.0 - a)
    p = out["coverage"]
    den = 1.0 + zq * zq / n
    mid = (p + zq * zq / (2 * n)) / den
    half = zq * np.sqrt(p * (1 - p) / n + zq * zq / (4 * n * n)) / den
    out.update({"se": float(np.std(c, ddof=1) / np.sqrt(n)) if n > 1 else float("nan"), "level": level,
                "boot": [lo, hi], "wilson": [float(mid - half), float(mid + half)],
                "consistent_boot": bool(lo <= target[1] and hi >= target[0]),
                "consistent_wilson": bool(mid - half <= target[1] and mid + half >= target[0])})
    return out


def pit(samples, r_true, weights=None) -> float:
    """Probability integral transform: predicted CDF at the true RUL (uniform when calibrated).

    Ties (discrete RUL steps) are split randomisation-free at the midpoint.
    """
    s = np.asarray(samples, float)
    w = _norm_w(len(s), weights)
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
    w = _norm_w(len(s), weights)
    o = np.argsort(s)
    s, w = s[o], w[o]
    c = np.cumsum(w)
    e1 = np.sum(w * np.abs(s - y))
    e2 = 2.0 * np.sum(w * s * (c + (c - w) - 1.0))
    return float(e1 - 0.5 * e2)


def inf_cap(t, t_eol: float, values, rul_horizon: float | None = None) -> tuple[float, str]:
    """The one value infinite RUL predictions are scored as: ``max(H, r*(t_p))`` (module docstring).

    ``t`` are the scored prediction times (t_p = t[0]), ``values`` every RUL
    array of the scored history (quantiles, samples). Returns (cap, rule).
    """
    r_max = float(t_eol - _arr(t)[0])
    if rul_horizon is not None and np.isfinite(rul_horizon):
        h, src = float(rul_horizon), "the forecast horizon (rul_horizon)"
    else:
        fin = [float(np.max(v[np.isfinite(v)])) for v in (np.asarray(x, float).ravel() for x in values)
               if np.isfinite(v).any()]
        h, src = (max(fin), "largest finite RUL in the history (forecast horizon unknown)") if fin else (r_max, "")
    return max(h, r_max), f"inf -> max(H, r*(t_p)), H = {src}" if src else "inf -> r*(t_p) (no finite RUL at all)"


def score_history(t, p50, p5, p95, t_eol: float, *, t_p: float | None = None, alpha: float = 0.2,
                  lambdas=(0.25, 0.5, 0.75), alpha_ph: float = 0.05, beta: float = 0.5,
                  samples=None, weights=None, rul_horizon: float | None = None,
                  convention: str = "hdphm") -> dict:
    """All metrics for one unit's RUL history (only predictions with t_p <= t < t_eol count).

    ``samples``/``weights`` (optional, one array per prediction) add the beta
    forms (``alpha_lambda_beta``, ``ph_beta``, ``ph_beta_sustained``), PIT
    and CRPS. ``rul_horizon``: the forecast horizon H for the infinite-value
    cap. ``convention`` selects the t_lambda rule, cone closure and RA form
    (module docstring); the output states the rules it used.
    """
    _check_convention(convention)
    t, p50, p5, p95 = _arr(t), _arr(p50), _arr(p5), _arr(p95)
    sel = t < t_eol
    if t_p is not None:
        sel &= t >= t_p
    if not sel.any():
        return {"n_predictions": 0, "t_eol": float(t_eol), "convention": convention}
    idx = np.flatnonzero(sel)
    t, p50, p5, p95 = t[sel], p50[sel], p5[sel], p95[sel]
    if samples is not None:
        samples = [np.asarray(samples[i], float) for i in idx]
        weights = None if weights is None else [weights[i] for i in idx]
    t_p = float(t[0]) if t_p is None else float(t_p)
    cap, cap_rule = inf_cap(t, t_eol, [p5, p50, p95] + (samples or []), rul_horizon)
    n_inf = int(sum(np.isposinf(v).sum() for v in [p5, p50, p95] + (samples or [])))

    def capped(v):
        return np.where(np.isposinf(v), cap, v)

    p5, p50, p95 = capped(p5), capped(p50), capped(p95)
    if samples is not None:
        samples = [capped(s) for s in samples]
    rt = t_eol - t
    err = np.abs(rt - p50)
    if convention == "hdphm":
        cra = cumulative_relative_accuracy(t, p50, t_eol)
    else:
        ws = [None] * len(t) if weights is None else weights
        ss = [[v] for v in p50] if samples is None else samples
        cra = float(sum(_progpy_ra(ti, s, w, t_eol) for ti, s, w in zip(t, ss, ws)) / len(t))
    out = {
        "convention": convention, **RULES[convention],
        "t_eol": float(t_eol), "t_p": t_p, "n_predictions": int(len(t)),
        "alpha": alpha, "lambdas": list(lambdas), "alpha_ph": alpha_ph, "beta": beta,
        "inf_cap": cap, "inf_cap_rule": cap_rule, "n_inf_capped": n_inf,
        "alpha_lambda_point": {str(k): v for k, v in alpha_lambda(
            t, p50, t_eol, t_p, alpha, lambdas, convention=convention).items()},
        "frac_in_cone_lambda_ge_0.5": fraction_in_cone(t, p50, t_eol, t_p, alpha, 0.5),
        "frac_in_cone_all": float(np.mean(in_alpha_cone(p50, rt, alpha))),
        "relative_accuracy_lambda_0.5": relative_accuracy_at(t, p50, t_eol, 0.5, t_p, samples=samples,
                                                             weights=weights, convention=convention),
        "cra": cra,
        "convergence": convergence(t, err, t_p),
        "ph_point": prognostic_horizon(t, t_eol, r_hat=p50, alpha=alpha_ph, convention=convention),
        "ph_point_sustained": prognostic_horizon(t, t_eol, r_hat=p50, alpha=alpha_ph, form="sustained",
                                                 convention=convention),
        "coverage_p5_p95": coverage(p5, p95, rt),
        "mae": float(np.mean(err)),
    }
    if samples is not None:
        out["alpha_lambda_beta"] = {str(k): v for k, v in alpha_lambda(
            t, p50, t_eol, t_p, alpha, lambdas, samples=samples, weights=weights, beta=beta,
            convention=convention).items()}
        for key, form in (("ph_beta", "first"), ("ph_beta_sustained", "sustained")):
            out[key] = prognostic_horizon(t, t_eol, samples=samples, weights=weights, alpha=alpha_ph, beta=beta,
                                          form=form, convention=convention)
        ws = [None] * len(samples) if weights is None else weights
        pits = [pit(s, r, w) for s, r, w in zip(samples, rt, ws)]
        out["pit"] = pits
        out["pit_ks"] = calibration_error(pits)
        out["crps_mean"] = float(np.mean([crps(s, r, w) for s, r, w in zip(samples, rt, ws)]))
    return out


# keys of reports written before issue 17 -> today's (the old PH key held the sustained form, of the samples
# when there were any, i.e. when PIT was reported, else of the median; old CRA/MAE were computed with finite
# medians clipped at 2 t_eol + 1 and cannot be un-clipped)
LEGACY_KEYS = {"alpha_lambda": "alpha_lambda_point"}


def upgrade_legacy(u: dict) -> dict:
    """A per-unit metrics dict of an old report with today's key names (no numbers changed)."""
    u = dict(u)
    for old, new in LEGACY_KEYS.items():
        if old in u and new not in u:
            u[new] = u.pop(old)
    if "prognostic_horizon" in u:
        v = u.pop("prognostic_horizon")
        u.setdefault("ph_beta_sustained" if "pit_ks" in u else "ph_point_sustained", v)
    return u


SCALAR_KEYS = ("frac_in_cone_lambda_ge_0.5", "frac_in_cone_all", "relative_accuracy_lambda_0.5", "cra",
               "convergence", "ph_point", "ph_point_sustained", "ph_beta", "ph_beta_sustained", "coverage_p5_p95",
               "mae", "pit_ks", "crps_mean")


def aggregate(per_unit: list[dict]) -> dict:
    """Mean across units of the scalar metrics (per-unit first, then average); one convention only."""
    per_unit = [upgrade_legacy(u) for u in per_unit]
    conv = {u.get("convention", "hdphm") for u in per_unit}
    if len(conv) > 1:
        raise ValueError(f"aggregate: per-unit metrics mix conventions {sorted(conv)}; score them with one")
    out = {"convention": conv.pop() if conv else "hdphm"}
    for k in SCALAR_KEYS:
        v = [u[k] for u in per_unit if k in u and u[k] is not None and np.isfinite(u[k])]
        if v:
            out[k] = float(np.mean(v))
    for form in ("point", "beta"):
        lam: dict[str, list] = {}
        for u in per_unit:
            for k, v in u.get(f"alpha_lambda_{form}", {}).items():
                if v is not None:
                    lam.setdefault(k, []).append(v)
        if lam:
            out[f"alpha_lambda_{form}_pass_rate"] = {k: float(np.mean(v)) for k, v in lam.items()}
    out["n_units"] = len(per_unit)
    return out
