"""The plain reference discovery is measured against: greedy least squares, what an engineer writes in an afternoon.

Baseline (tau_m): inertia alpha_m + load path Q_red/N + Coulomb tanh(omega_m/eps) + viscous omega_m, with eps
picked from 8 values on the fit bags (least squares); (Q_red): K w + c w'. Then greedy forward selection over
the same kinds of terms discovery considers (harmonics of theta_m / theta_f, plain and times sgn(omega_m),
position-dependent stiffness, Stribeck at a few speeds, load-dependent and temperature-dependent friction, the
torque constant's drift with temperature, drag, bias, cubic stiffness, a dead zone at a few widths, hysteresis),
each group scored by its **held-out** error (the held-out bag itself, as such a script does: optimistic for the
reference), stopping when the best group lowers it by less than ``min_gain``. No identifiability test, no
uncertainty, shapes from fixed grids.

``select="cv"``: the same search scored by leave-one-bag-out cross-validation over the fit bags instead (each fit
bag predicted from the others), the held-out bag used only for the final score: the variant an engineer who does
not peek at the test bag writes. It shows how much of the held-out reference's lead is its choice on that bag.
"""

from __future__ import annotations

import numpy as np

from .data import Dataset


def _lstsq(X, y):
    s = np.sqrt(np.mean(X**2, 0)) + 1e-300
    return np.linalg.lstsq(X / s, y, rcond=None)[0] / s


def _groups(sig: dict, target: str, eps: float, avail: set[str],
            t_ref: float | None = None) -> list[tuple[str, str | None, float | None, list]]:
    """(name, variable, order, [columns]) of the candidate groups. ``t_ref``: the temperature offsets' reference (the
    fit rows' median; default the median of ``sig``). It matters for the torque constant's drift, whose column is
    the current (the target over k_t) times T - t_ref: another reference adds a multiple of the target itself."""
    w = sig["omega_m"]
    sg = np.tanh(w / eps)
    g = []
    for var, orders in (("theta_m", (1, 2, 3, 4, 6)), ("theta_f", (1, 2, 3))):
        if var not in avail:
            continue
        for k in orders:
            s, c = np.sin(k * sig[var]), np.cos(k * sig[var])
            if target == "tau_m":
                g.append(("position_periodic_torque", var, float(k), [s, c]))
                g.append(("position_periodic_friction", var, float(k), [s * sg, c * sg]))
            elif var == "theta_m":
                g.append(("kinematic_error_harmonic", var, float(k), [s, c]))
                if "windup" in avail:
                    g.append(("position_dependent_stiffness", var, float(k), [s * sig["windup"], c * sig["windup"]]))
    g.append(("unknown", None, None, [np.ones_like(w)]))  # bias
    if target == "tau_m":
        scale = float(np.quantile(np.abs(w), 0.9))
        for ws in np.geomspace(0.02, 0.5, 4) * scale:
            g.append(("stribeck_friction", "omega_m", None, [np.exp(-((np.abs(w) / ws) ** 2)) * sg]))
        if "Q_red" in avail:
            g.append(("load_dependent_friction", "Q_red", None, [np.abs(sig["Q_red"]) * sg]))
        if "temperature" in avail:
            dT = sig["temperature"] - (np.median(sig["temperature"]) if t_ref is None else t_ref)
            g.append(("temperature_dependent_friction", "temperature", None, [w * dT, sg * dT]))
            if "i_q" in avail:  # the torque constant's drift: the current scaled by the temperature offset
                g.append(("motor_thermal_drift", "temperature", None, [sig["i_q"] * dT]))
        g.append(("unknown", "omega_m", None, [w * np.abs(w)]))  # drag
    elif "windup" in avail:
        wu = sig["windup"]
        g.append(("nonlinear_stiffness", "windup", None, [wu**3]))
        g.append(("nonlinear_stiffness", "windup", None, [wu * np.abs(wu)]))  # the same kinds of terms as discover's
        sc = float(np.quantile(np.abs(wu), 0.9))
        for j in np.geomspace(0.02, 0.3, 4) * sc:
            dz = np.sign(wu) * np.maximum(np.abs(wu) - j, 0.0)
            g.append(("backlash", "windup", None, [dz, dz**3]))
        if "windup_dot" in avail:
            g.append(("hysteresis", "windup", None, [np.sign(sig["windup_dot"])]))
    return g


def greedy_discover(ds: Dataset, target: str, heldout: np.ndarray, *, min_gain: float = 0.02,
                    max_terms: int = 6, standstill: np.ndarray | None = None, select: str = "heldout") -> dict:
    """Greedy least-squares discovery of ``target``; returns errors before/after and the found effects.
    ``select``: "heldout" (groups scored on the held-out bag, the reference) or "cv" (leave-one-bag-out over the
    fit bags; needs >= 2 fit bags)."""
    if select not in ("heldout", "cv"):
        raise ValueError(f"greedy_discover: select must be 'heldout' or 'cv', not {select!r}")
    sig = ds.signals
    keep = np.ones(ds.n, bool) if standstill is None else ~standstill
    sig = {k: v[keep] for k, v in sig.items()}
    ho = heldout[keep]
    fit = ~ho
    fit_bags = np.unique(ds.bag[keep][fit])
    if select == "cv" and len(fit_bags) < 2:
        raise ValueError(f"greedy_discover: select='cv' needs >= 2 fit bags, got {len(fit_bags)}")
    bag = ds.bag[keep]
    avail = {k for k, v in sig.items() if np.std(v) > 0}
    y = sig[target]
    w = sig["omega_m"]
    if target == "tau_m":
        scale = float(np.quantile(np.abs(w[fit]), 0.9))
        best = None
        for eps in np.geomspace(1e-3, 0.3, 8) * scale:
            cols = [sig["alpha_m"], np.tanh(w / eps), w] + ([sig["Q_red_over_N"]] if "Q_red_over_N" in avail else []) + (
                [sig["alpha_m_dot"]] if "alpha_m_dot" in avail else [])  # discover's acceleration timing, if chosen
            X = np.stack(cols, 1)
            r = y[fit] - X[fit] @ _lstsq(X[fit], y[fit])
            if best is None or r @ r < best[0]:
                best = (float(r @ r), eps, X)
        _, eps, Xb = best
    else:
        eps = float(np.quantile(np.abs(w[fit]), 0.9)) * 1e-2
        # the same Q_red baseline discover fits: stiffness, damping and the output inertia (core.baseline_columns)
        Xb = np.stack([sig["windup"], sig["windup_dot"]] + ([sig["alpha_f"]] if "alpha_f" in avail else []), 1)

    def ho_sse(X):
        b = _lstsq(X[fit], y[fit])
        r = (y - X @ b)[ho]
        return float(r @ r), b

    def cv_sse(X):  # leave-one-bag-out over the fit bags
        e = 0.0
        for k in fit_bags:
            tr, te = fit & (bag != k), bag == k
            r = y[te] - X[te] @ _lstsq(X[tr], y[tr])
            e += float(r @ r)
        return e

    score = (lambda X: ho_sse(X)[0]) if select == "heldout" else cv_sse

    groups = _groups(sig, target, eps, avail,
                     float(np.median(sig["temperature"][fit])) if "temperature" in avail else None)
    X = Xb
    before, _ = ho_sse(X)
    cur = score(X)
    chosen = []
    used = set()
    while len(chosen) < max_terms:
        trial = [(score(np.column_stack([X] + cols)), i) for i, (_, _, _, cols) in enumerate(groups) if i not in used]
        if not trial:
            break
        e, i = min(trial)
        if (cur - e) / cur < min_gain:
            break
        used.add(i)
        X = np.column_stack([X] + groups[i][3])
        chosen.append(i)
        cur = e
    cur, beta = ho_sse(X)
    r_ho = (y - X @ beta)[ho]
    effects, pos = [], Xb.shape[1]
    for i in chosen:
        name, var, order, cols = groups[i]
        c = beta[pos:pos + len(cols)]
        pos += len(cols)
        params = {"amplitude": float(np.hypot(*c))} if len(cols) == 2 and order is not None else {
            f"c{j}": float(v) for j, v in enumerate(c)}
        effects.append({"name": name, "variable": var, "order": order, "parameters": params})
    n = int(ho.sum())
    sd = float(np.std(y[ho]))
    err = lambda sse: {"rmse": float(np.sqrt(sse / n)), "nrmse": float(np.sqrt(sse / n)) / sd, "n": n}
    return {"signal": target, "select": select, "eps": float(eps), "error_before": err(before), "error_after": err(cur),
            "effects": effects, "residual_heldout": r_ho}
