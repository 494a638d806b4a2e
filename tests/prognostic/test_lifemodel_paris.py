"""Crack-growth (Paris-type) latent path family: chosen by AIC on units that grow like cracks, not on a
power-law fleet; where chosen, its forecast beats the power law's on new units."""

from __future__ import annotations

import math

import numpy as np

from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory
from tests.prognostic.lifesynth import forecast_scores, synth_units


def paris_units(n: int, seed: int, a0: float = 9.0, m: float = 3.0, af: float = 40.0, every: float = 8.0,
                noise: float = 0.2):
    """Crack length by Paris' law with dK ~ sqrt(a) integrated, a(N) = a0 (1 - N/N_b)^(-2/(m-2)), per-unit
    C (log-normal blow-up cycles N_b); failure = first record with a >= af (found there)."""
    rng = np.random.default_rng(seed)
    p = 2.0 / (m - 2.0)
    units, eol = [], {}
    for i in range(n):
        Nb = 300.0 * math.exp(rng.normal(0.0, 0.25))
        t = np.arange(0.0, 2 * Nb, every)
        a = a0 * (1.0 - np.minimum(t / Nb, 1 - 1e-9)) ** (-p)
        kf = int(np.argmax(a >= af))
        u = f"P{i:02d}"
        units.append(UnitHistory(u, t[:kf], a[:kf] + rng.normal(0.0, noise, kf), t[:kf].copy(), discrete=False,
                                 events=UnitEvents(failure=float(t[kf]))))
        eol[u] = float(t[kf])
    return units, eol


def test_crack_growth_fleet_chooses_paris_and_forecasts_better():
    units, _ = paris_units(8, seed=1, every=10.0)
    test, eol = paris_units(3, seed=9, every=10.0)
    m = LifeModel.fit(units, threshold="latent", path="auto", n_draws=0)
    assert m.path == "paris"
    aic = m.fit_info["path_aic"]
    assert aic["paris"] < aic["power"] - 10.0
    pw = LifeModel.fit(units, threshold=m.threshold, path="power", n_draws=0)  # same threshold kind
    _, _, crps_p = forecast_scores(m, test, eol)
    _, _, crps_w = forecast_scores(pw, test, eol)
    assert crps_p < 0.8 * crps_w
    m2 = LifeModel.from_json(m.to_json())  # the model file keeps the family
    assert m2.path == "paris"
    assert np.allclose(m2.log_marginal(test[:1]), m.log_marginal(test[:1]))


def test_power_law_fleet_keeps_the_power_law():
    units, _ = synth_units(6, seed=3, censor_frac=0.25, max_t=300)
    m = LifeModel.fit(units, threshold="latent", path="auto", n_draws=0)
    assert m.path == "power"
    assert m.fit_info["path_aic"]["power"] < m.fit_info["path_aic"]["paris"]
