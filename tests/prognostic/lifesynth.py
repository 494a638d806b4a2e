"""Synthetic fleets drawn from the life model's own generative law (known parameters), for tests."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from hd_prognostic import metrics as M
from hd_prognostic.lifemodel import UnitEvents, UnitHistory, predict_history

#: the shared measured data (NASA cells, Virkler): $HDPHM_MEASURED_DATA, else the shared folder next to the
#: repository checkout (tests only; the package takes data paths as arguments)
MEASURED = Path(os.environ.get("HDPHM_MEASURED_DATA") or
                Path(__file__).resolve().parents[3] / "shared" / "data" / "measured")
if not MEASURED.is_dir():
    MEASURED = Path("/work/shared/data/measured")

TRUTH = {"mu": 0.0, "s": 0.25, "b": 1.6, "c": 2.0, "a0": 1.0, "sa": 0.3, "sigma": 0.08, "sD": 0.10}
E_REF = 100.0  # missions


def synth_units(n: int, seed: int, truth: dict = TRUTH, censor_frac: float = 0.3, max_t: int = 1000,
                inspect_every: int = 0) -> tuple[list[UnitHistory], dict]:
    """n units: HI every mission until the failure (found at the start of mission k_f) or a removal."""
    rng = np.random.default_rng(seed)
    units, eol = [], {}
    for i in range(n):
        z = rng.normal(truth["mu"], truth["s"])
        lnD = rng.normal(0.0, truth["sD"])
        Ef = E_REF * math.exp((lnD - z) / truth["b"])
        kf = int(math.ceil(Ef))  # first mission whose start exposure reaches E_f
        a = rng.normal(truth["a0"], truth["sa"])
        ev = UnitEvents()
        last = kf - 1
        if rng.random() < censor_frac:
            rem = int(rng.integers(max(2, kf // 3), kf))
            ev.removal = float(rem)
            last = rem - 1
        else:
            ev.failure = float(kf)
        t = np.arange(0, min(last, max_t) + 1, dtype=float)
        y = a + truth["c"] * math.exp(z) * (t / E_REF) ** truth["b"] + rng.normal(0, truth["sigma"], len(t))
        if inspect_every:
            for ti in t[inspect_every::inspect_every]:
                L = math.exp(z) * (ti / E_REF) ** truth["b"]
                ev.inspections.append((float(ti), "wear_depth", 40e-6 * L + rng.normal(0, 1e-6)))
        units.append(UnitHistory(f"U{i:02d}", t, y, t.copy(), discrete=True, E_next=float(t[-1] + 1),
                                 events=ev))
        eol[f"U{i:02d}"] = kf
    return units, eol


TRUTH_OBS = {"s": 0.25, "b": 1.6, "c": 2.0, "a0": 1.0, "sa": 0.3, "sigma": 0.08, "rho": 0.8, "Y0": 3.0, "sY": 0.03}


def synth_units_observable(n: int, seed: int, truth: dict = TRUTH_OBS,
                           max_t: int = 2000) -> tuple[list[UnitHistory], dict]:
    """n units whose failure is defined on the *measured* HI: the first mission whose HI record reaches the
    unit's level Y_i ~ N(Y0, sY^2) (as NASA's capacity or Virkler's crack length); AR(1) HI noise, so a unit's
    measurement runs persistently ahead of or behind its smooth path. Records before that mission are kept."""
    rng = np.random.default_rng(seed)
    units, eol = [], {}
    for i in range(n):
        z = rng.normal(0.0, truth["s"])
        a = rng.normal(truth["a0"], truth["sa"])
        Y = rng.normal(truth["Y0"], truth["sY"])
        t = np.arange(0, max_t + 1, dtype=float)
        e = np.empty(len(t))
        e[0] = rng.normal(0, truth["sigma"] / math.sqrt(1 - truth["rho"] ** 2))
        xi = rng.normal(0, truth["sigma"], len(t))
        for k in range(1, len(t)):
            e[k] = truth["rho"] * e[k - 1] + xi[k]
        y = a + truth["c"] * math.exp(z) * (t / E_REF) ** truth["b"] + e
        kf = int(np.argmax(y >= Y))
        if kf < 3:  # failed on arrival: redraw-free skip (kept deterministic by the seed)
            continue
        u = f"V{i:02d}"
        units.append(UnitHistory(u, t[:kf], y[:kf], t[:kf].copy(), discrete=True, E_next=float(kf),
                                 events=UnitEvents(failure=float(kf))))
        eol[u] = kf
    return units, eol


def forecast_scores(m, test, eol: dict, n_samples: int = 300) -> tuple[float, float, float]:
    """Mean (P5-P95 coverage, in-cone fraction for lambda >= 0.5, CRPS) of ``m``'s prognosis over the new units
    ``test`` (each forecast from its own record only, scored against its failure ``eol[unit]``)."""
    cov, ic, crps = [], [], []
    for u in test:
        h = predict_history(m, UnitHistory(u.unit, u.t, u.y, u.E, u.discrete, u.E_next), n_samples=n_samples,
                            seed=0)
        s = M.score_history(h.rul_t, h.p50, h.p5, h.p95, eol[u.unit], samples=h.samples)
        cov.append(s["coverage_p5_p95"])
        ic.append(s["frac_in_cone_lambda_ge_0.5"])
        crps.append(s["crps_mean"])
    return float(np.mean(cov)), float(np.mean(ic)), float(np.mean(crps))
