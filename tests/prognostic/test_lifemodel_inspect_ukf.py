"""The UKF prognosis uses a unit's own inspections (as the grid posterior does): known-answer synthetic unit.

A model with the generative law's own parameters (no fit) and an exact wear-depth map (40 um at the median
threshold, 1 um gauge sd); one held-out unit whose HI offset is far off the population mean, so its HI alone
fixes its rate only loosely. With its inspections the filter's latent state must sit on the unit's true degradation,
as tight as the exact grid posterior's; without them it is not (the filter ignored inspections before).
"""

from __future__ import annotations

import math

import numpy as np

from tests.prognostic.lifesynth import E_REF, TRUTH
from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory, predict_history

SIGMA = 0.5  # a noisy HI (sd a quarter of its change at the median threshold): it pins the rate only loosely
THETA = {"mu": TRUTH["mu"], "log_s": math.log(TRUTH["s"]), "log_b": math.log(TRUTH["b"]), "c": TRUTH["c"],
         "a0": TRUTH["a0"], "log_sa": math.log(TRUTH["sa"]), "log_sigma": math.log(SIGMA),
         "log_sD": math.log(TRUTH["sD"]), "atanh_rho": 0.0}
MAP = {"wear_depth": {"alpha": 0.0, "beta": 40e-6, "log_tau": math.log(1e-6)}}


def _unit(inspect: bool):
    rng = np.random.default_rng(5)
    z = TRUTH["mu"] + 2.0 * TRUTH["s"]  # a fast unit (+2 sd)...
    a = TRUTH["a0"] - 2.5 * TRUTH["sa"]  # ...whose HI starts low: the HI alone reads it as an average one
    t = np.arange(0, 61, dtype=float)
    y = a + TRUTH["c"] * math.exp(z) * (t / E_REF) ** TRUTH["b"] + rng.normal(0, SIGMA, len(t))
    ev = UnitEvents()
    if inspect:
        for ti in (20.0, 40.0, 60.0):  # overhauls every 20 missions
            ev.inspections.append((ti, "wear_depth", 40e-6 * math.exp(z) * (ti / E_REF) ** TRUTH["b"]
                                   + rng.normal(0, 1e-6)))
    u = UnitHistory("H", t, y, t.copy(), discrete=True, E_next=float(t[-1] + 1), events=ev)
    return u, math.exp(z) * (t[-1] / E_REF) ** TRUTH["b"]


def _latent(method: str, inspect: bool):
    m = LifeModel(THETA, E_REF, inspections=MAP)
    u, L_true = _unit(inspect)
    h = predict_history(m, u, n_samples=4000, seed=1, method=method)
    return h.state_p5[-1][0], h.state_mean[-1][0], h.state_p95[-1][0], L_true


def test_ukf_uses_the_units_inspections():
    p5, p50, p95, L = _latent("ukf", True)
    g5, g50, g95, _ = _latent("grid", True)
    n5, n50, n95, _ = _latent("ukf", False)
    # the grid posterior (exact) with the inspections: on the truth (3 readings of 1 um on ~40 um: ~1.5 %)
    assert g5 < L < g95 and abs(g50 / L - 1) < 0.05, (g5, g50, g95, L)
    # the UKF with them: the same answer, as tight
    assert p5 < L < p95 and abs(p50 / L - 1) < 0.05, (p5, p50, p95, L)
    assert (p95 - p5) < 2.0 * (g95 - g5) + 0.02 * L, (p5, p95, g5, g95)
    # without them (what the filter did before it read inspections) the HI alone leaves it far less certain
    assert (n95 - n5) > 3.0 * (p95 - p5), (n5, n50, n95, p5, p95, L)
