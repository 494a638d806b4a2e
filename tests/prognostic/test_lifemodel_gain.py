"""Per-unit HI gain (``LifeModel.fit(hi_gain=...)``): known answers on synthetic units.

The model ``y = a_i + c (1 + g_i) L + e``, ``g_i ~ N(0, s_g^2)``, with the offset and the gain marginalised in
closed form (``_Batch._gain_terms``). Checked: the closed form against a brute-force multivariate normal
density (AR(1) residuals, level-dependent noise); on a fleet whose HI gain scatters 25 % between units and whose
units carry wear-depth inspections, the fit recovers the scatter, AIC keeps the per-unit gain, the threshold
scatter is no longer inflated by it, and the forecasts of new units (grid posterior and the 3-state UKF) beat the
shared-gain fit's; a fleet with one shared gain keeps the shared gain by AIC.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from hd_prognostic import metrics as M
from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory, _Batch, predict_history
from tests.prognostic.lifesynth import E_REF

T = {"mu": 0.0, "s": 0.25, "b": 1.6, "c": 2.0, "a0": 1.0, "sa": 0.3, "sigma": 0.08, "sD": 0.05, "sg": 0.25}


def _units(n: int, seed: int, sg: float, every: int = 10):
    """n failed units, HI every mission, a wear-depth reading (40 um at the median threshold, 1 um sd) every
    ``every`` missions; the unit's HI gain c (1 + g_i), g_i ~ N(0, sg^2)."""
    rng = np.random.default_rng(seed)
    out, eol = [], {}
    for i in range(n):
        z, lnD, g = rng.normal(T["mu"], T["s"]), rng.normal(0.0, T["sD"]), rng.normal(0.0, sg)
        kf = int(math.ceil(E_REF * math.exp((lnD - z) / T["b"])))
        a = rng.normal(T["a0"], T["sa"])
        t = np.arange(0, kf, dtype=float)
        L = math.exp(z) * (t / E_REF) ** T["b"]
        y = a + T["c"] * (1.0 + g) * L + rng.normal(0.0, T["sigma"], len(t))
        ev = UnitEvents(failure=float(kf))
        for ti in (t[every::every] if every else ()):
            ev.inspections.append((float(ti), "wear_depth",
                                   40e-6 * math.exp(z) * (ti / E_REF) ** T["b"] + rng.normal(0.0, 1e-6)))
        u = f"U{i:02d}"
        out.append(UnitHistory(u, t, y, t.copy(), discrete=True, E_next=float(t[-1] + 1), events=ev))
        eol[u] = kf
    return out, eol


THETA = {"mu": 0.0, "log_s": math.log(0.25), "log_b": math.log(1.6), "c": 2.0, "a0": 1.0, "log_sa": math.log(0.3),
         "log_sigma": math.log(0.08), "log_sD": math.log(0.1), "atanh_rho": 0.0}


@pytest.mark.parametrize("rho,kappa", [(0.0, None), (0.6, 0.5)])
def test_gain_likelihood_is_the_marginal_normal(rho, kappa):
    """log p(y | z) with (offset, gain) marginalised equals the multivariate normal density of the record with
    covariance sigma^2 s s' R(rho) + s_a^2 + (c s_g)^2 L L' (R the AR(1) correlation, s the level noise's scale)."""
    units, _ = _units(3, 1, 0.0, every=0)
    th = dict(THETA, log_sg=math.log(0.2), atanh_rho=math.atanh(rho))
    if kappa:
        th["log_kappa"] = math.log(kappa)
    z = np.tile(np.linspace(-0.4, 0.4, 5), (len(units), 1))
    bt = _Batch(units, E_REF)
    f = bt.logf(z, th, T["b"], {})
    ev = f - _Batch(units, E_REF).logf(z, dict(th, log_sg=-30.0), T["b"], {})  # same event term in both...
    for i, u in enumerate(units):
        ref = []
        for zz in z[i]:
            L = math.exp(zz) * (u.E / E_REF) ** T["b"]
            s = np.sqrt(1.0 + (kappa or 0.0) ** 2 * L ** 2)
            k = np.arange(len(u.y))
            R = rho ** np.abs(k[:, None] - k[None, :]) / (1.0 - rho * rho)
            C = 0.08 ** 2 * np.outer(s, s) * R + 0.3 ** 2 + (2.0 * 0.2) ** 2 * np.outer(L, L)
            ref.append(stats.multivariate_normal(1.0 + 2.0 * L, C).logpdf(u.y))
        ref0 = []  # ...and the shared-gain limit (s_g -> 0) is the same density without the gain term
        for zz in z[i]:
            L = math.exp(zz) * (u.E / E_REF) ** T["b"]
            s = np.sqrt(1.0 + (kappa or 0.0) ** 2 * L ** 2)
            k = np.arange(len(u.y))
            R = rho ** np.abs(k[:, None] - k[None, :]) / (1.0 - rho * rho)
            ref0.append(stats.multivariate_normal(1.0 + 2.0 * L, 0.08 ** 2 * np.outer(s, s) * R + 0.3 ** 2).logpdf(u.y))
        np.testing.assert_allclose(ev[i], np.array(ref) - np.array(ref0), rtol=1e-6, atol=1e-6)
    # the s_g -> 0 limit of the gain likelihood is the shared-gain likelihood
    f0 = _Batch(units, E_REF).logf(z, {k: v for k, v in th.items() if k != "log_sg"}, T["b"], {})
    f1 = _Batch(units, E_REF).logf(z, dict(th, log_sg=-30.0), T["b"], {})
    np.testing.assert_allclose(f1, f0, rtol=1e-9, atol=1e-6)


def _score(m, units, eol, method):
    out = []
    for u in units:
        test = UnitHistory(u.unit, u.t, u.y, u.E, discrete=True, E_next=u.E_next,
                           events=UnitEvents(inspections=list(u.events.inspections)))  # its failure unknown
        h = predict_history(m, test, n_samples=400, seed=1, method=method)
        s = M.score_history(h.rul_t, h.p50, h.p5, h.p95, float(eol[u.unit]), alpha=0.2, samples=h.samples)
        out.append([s["frac_in_cone_lambda_ge_0.5"], s["coverage_p5_p95"], s["crps_mean"]])
    return np.mean(out, 0)


@pytest.fixture(scope="module")
def gain_fleet_fits():
    train, _ = _units(10, 3, T["sg"])
    test, eol = _units(4, 99, T["sg"])
    shared = LifeModel.fit(train, n_draws=8, seed=0, hi_gain="shared")
    auto = LifeModel.fit(train, n_draws=8, seed=0, hi_gain="auto")
    return shared, auto, test, eol


def test_per_unit_gain_is_recovered_and_kept(gain_fleet_fits):
    shared, auto, _, _ = gain_fleet_fits
    assert auto.fit_info["hi_gain"] == "unit", auto.fit_info.get("gain_aic")
    assert auto.fit_info["gain_aic"]["unit"] < auto.fit_info["gain_aic"]["shared"] - 10
    sg = math.exp(auto.theta["log_sg"])
    assert 0.12 < sg < 0.45, sg  # 25 % from 10 units
    # the shared gain leaves the gain's scatter to the threshold's (true 0.05): the per-unit gain does not
    assert math.exp(shared.theta["log_sD"]) > 2.0 * math.exp(auto.theta["log_sD"]), (shared.theta, auto.theta)
    assert math.exp(auto.theta["log_sD"]) < 0.1


@pytest.mark.parametrize("method", ["grid", "ukf"])
def test_per_unit_gain_forecasts_new_units_better(gain_fleet_fits, method):
    shared, auto, test, eol = gain_fleet_fits
    ic_s, cov_s, crps_s = _score(shared, test, eol, method)
    ic_u, cov_u, crps_u = _score(auto, test, eol, method)
    assert ic_u > ic_s + 0.2, (ic_s, ic_u)
    assert crps_u < 0.85 * crps_s, (crps_s, crps_u)
    assert cov_u >= 0.75, cov_u


def test_shared_gain_fleet_keeps_the_shared_gain():
    train, _ = _units(8, 5, 0.0)
    m = LifeModel.fit(train, n_draws=0, seed=0, hi_gain="auto")
    assert m.fit_info["hi_gain"] == "shared", m.fit_info["gain_aic"]
    assert "log_sg" not in m.theta
