"""Level-dependent HI noise (``LifeModel.fit(noise="level"|"auto")``: record sd ``sigma sqrt(1 + kappa^2 L^2)``,
standardised residuals AR(1)), the sampling uncertainty of a unit's mean exposure rate
(``exposure_spread="renewal+rate"``) and the renewal spread in the observable-threshold prognosis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory, _Batch

from .lifesynth import E_REF, TRUTH, synth_units


def _level_units(n: int, seed: int, kappa: float, sigma: float = 0.03, rho: float = 0.3):
    """Units from the life model's law with record sd sigma sqrt(1 + kappa^2 L^2) and AR(1) standardised residuals
    (the noise grows with the degradation: 1 + kappa^2 at the median threshold)."""
    rng = np.random.default_rng(seed)
    units = []
    for i in range(n):
        z = rng.normal(TRUTH["mu"], TRUTH["s"])
        lnD = rng.normal(0.0, TRUTH["sD"])
        kf = int(math.ceil(E_REF * math.exp((lnD - z) / TRUTH["b"])))
        t = np.arange(0, kf, dtype=float)
        L = math.exp(z) * (t / E_REF) ** TRUTH["b"]
        eps = np.empty(len(t))
        eps[0] = rng.normal(0.0, sigma / math.sqrt(1 - rho * rho))
        for j in range(1, len(t)):
            eps[j] = rho * eps[j - 1] + rng.normal(0.0, sigma)
        y = rng.normal(TRUTH["a0"], TRUTH["sa"]) + TRUTH["c"] * L + eps * np.sqrt(1.0 + (kappa * L) ** 2)
        units.append(UnitHistory(f"U{i:02d}", t, y, t.copy(), discrete=True, E_next=float(t[-1] + 1),
                                 events=UnitEvents(failure=float(kf))))
    return units


TH = {"mu": 0.05, "log_s": math.log(0.25), "log_b": math.log(1.6), "c": 2.0, "a0": 1.0, "log_sa": math.log(0.3),
      "log_sigma": math.log(0.08), "log_sD": math.log(0.1), "atanh_rho": math.atanh(0.4), "log_D0": 0.3}


@pytest.mark.parametrize("path", ["power", "paris"])
def test_level_noise_at_kappa_zero_is_the_constant_model(path):
    """The per-record (z-dependent) sums of the level-dependent noise reduce to the constant model's likelihood,
    offset posterior and observable event terms as kappa -> 0 (two code paths, one model)."""
    units, _ = synth_units(5, seed=3)
    bt = _Batch(units, E_REF, path=path)
    z = np.linspace(-1.0, 0.6, 41)[None, :].repeat(len(units), 0)
    th = dict(TH) if path == "paris" else {k: v for k, v in TH.items() if k != "log_D0"}
    b = math.exp(th["log_b"])
    if path == "paris":  # a time scale: keep every record before the blow-up
        b, th["log_b"], z = 1.0, 0.0, z - 1.5
    thk = dict(th, log_kappa=-40.0)
    f0, f1 = bt.logf(z, th, b, {}), bt.logf(z, thk, b, {})
    ok = np.isfinite(f0)
    assert ok.mean() > 0.9 and np.array_equal(ok, np.isfinite(f1))
    assert np.allclose(f0[ok], f1[ok], rtol=1e-9, atol=1e-6)
    m0, v0 = bt.a_post(np.exp(z), th, b, z)
    m1, v1 = bt.a_post(np.exp(z), thk, b, z)
    assert np.allclose(m0, m1, rtol=1e-9) and np.allclose(v0, v1, rtol=1e-9)
    tho = {k: v for k, v in th.items() if k != "log_sD"} | {"Y0": 4.0, "log_sY": math.log(0.2)}
    o0 = bt._obs_event_terms(z, np.exp(z), tho, b, math.tanh(th["atanh_rho"]), 0.3, 0.08, 2.0, 1.0)
    o1 = bt._obs_event_terms(z, np.exp(z), dict(tho, log_kappa=-40.0), b, math.tanh(th["atanh_rho"]), 0.3, 0.08,
                             2.0, 1.0)
    assert np.allclose(o0, o1, rtol=1e-9, atol=1e-9)


def test_level_noise_recovered_and_chosen_by_aic():
    """kappa = 2 (the record sd 2.2x larger at the median threshold than new): ``noise="auto"`` keeps the level
    model by AIC and recovers kappa and the noise floor; on a constant-noise fleet it keeps the constant one."""
    units = _level_units(6, seed=6, kappa=2.0)
    m = LifeModel.fit(units, n_draws=0, noise="auto")
    assert m.fit_info["noise"] == "level"
    assert m.fit_info["noise_rule"]["regular"]  # interior, identified: the guard lets AIC compare it
    lo, hi = m.fit_info["noise_rule"]["wald"]["log_kappa"]
    assert lo < math.log(2.0) < hi
    aic = m.fit_info["noise_aic"]
    assert aic["constant"] - aic["level"] > 20
    assert math.exp(m.theta["log_kappa"]) == pytest.approx(2.0, rel=0.3)
    assert math.exp(m.theta["log_sigma"]) == pytest.approx(0.03, rel=0.2)
    assert m.to_json()["readable"]["hi_noise_level_kappa"] == pytest.approx(math.exp(m.theta["log_kappa"]))
    const, _ = synth_units(6, seed=6, censor_frac=0.0)
    mc = LifeModel.fit(const, n_draws=0, noise="auto")
    assert mc.fit_info["noise"] == "constant" and "log_kappa" not in mc.theta
    with pytest.raises(ValueError, match="noise"):
        LifeModel.fit(const, noise="heteroscedastic")


THETA = {"mu": 0.0, "log_s": np.log(0.3), "log_b": np.log(2.0), "c": 1.0, "a0": 0.0, "log_sa": np.log(0.1),
         "log_sigma": np.log(0.05), "log_sD": np.log(0.1), "atanh_rho": 0.0}
INC = np.tile([0.7, 1.3], 20)  # per-step exposure: mean 1, variance 0.09 (x 40/39 as a sample variance)


def _unit(y=None):
    t = np.arange(len(INC) + 1.0)
    E = np.concatenate([[0.0], np.cumsum(INC)])
    return UnitHistory("U", t, np.zeros(len(t)) if y is None else y(E), E, discrete=True, E_next=float(E[-1] + 1.0))


def test_mean_rate_uncertainty_adds_its_variance():
    """``renewal+rate``: the rate of each sample is drawn from its sampling law (variance v / n = cv^2 m^2 / n);
    the RUL variance grows by (D / m)^2 var(m) / m^2 (delta method) over the renewal spread, mean unchanged."""
    u = _unit()
    fi = {"exposure_rate": "mean"}
    ren = LifeModel(THETA, E_ref=140.0, fit_info=dict(fi, exposure_spread="renewal"))
    both = LifeModel(THETA, E_ref=140.0, fit_info=dict(fi, exposure_spread="renewal+rate"))
    n = 40000
    z = np.zeros(n)
    a = both.rul_samples(z, u, 40.0, np.random.default_rng(3))
    b = ren.rul_samples(z, u, 40.0, np.random.default_rng(3))
    m, vm = u.rate("mean"), u.rate_mean_var()
    assert vm == pytest.approx(u.rate_var() / len(INC))
    D = np.mean(b - 1.0) * m  # remaining exposure after the known next step
    expected = (D / m) ** 2 * vm / m ** 2
    assert 15.0 < expected < 30.0  # cv 0.3 over 40 steps: ~5 % of a ~100-step RUL
    assert np.var(a) - np.var(b) == pytest.approx(expected, rel=0.2)
    assert np.mean(a) == pytest.approx(np.mean(b), abs=0.5)
    # exposure = time (no increment variance): no draw, bit for bit
    uc = UnitHistory("C", np.arange(41.0), np.zeros(41), np.arange(41.0), discrete=True, E_next=41.0)
    assert uc.rate_mean_var() == 0.0
    assert np.array_equal(both.rul_samples(z[:500], uc, 40.0, np.random.default_rng(4)),
                          ren.rul_samples(z[:500], uc, 40.0, np.random.default_rng(4)))


def test_observable_threshold_gets_the_renewal_spread():
    """Observable threshold, a near-deterministic HI path and level: the RUL spread is the renewal passage time's,
    var ~ D v / m^3 (as the latent threshold's inverse-Gaussian draw), with the same mean as the single rate."""
    th = {"mu": 0.0, "log_s": np.log(0.3), "log_b": np.log(2.0), "c": 1.0, "a0": 0.0, "log_sa": np.log(1e-6),
          "log_sigma": np.log(1e-6), "Y0": 1.0, "log_sY": np.log(1e-6), "atanh_rho": 0.0}
    u = _unit(lambda E: (E / 140.0) ** 2)  # z = 0: the HI reaches Y0 = 1 at E = 140
    fi = {"exposure_rate": "mean"}
    ren = LifeModel(th, E_ref=140.0, fit_info=dict(fi, exposure_spread="renewal"))
    none = LifeModel(th, E_ref=140.0, fit_info=dict(fi, exposure_spread="none"))
    z = np.zeros(8000)
    a = ren.rul_samples(z, u, 40.0, np.random.default_rng(5))
    b = none.rul_samples(z, u, 40.0, np.random.default_rng(5))
    assert np.std(b) < 0.6  # the single rate: one step (to the rounding of the threshold's draw)
    m, v = u.rate("mean"), u.rate_var()
    expected = (140.0 - u.E_next) * v / m ** 3
    assert np.var(a) == pytest.approx(expected + np.var(b), rel=0.2)
    assert np.mean(a) == pytest.approx(np.mean(b), abs=0.5)
