"""Particle filter, resampling, RUL and UKF on synthetic models with known truth."""

import numpy as np
import pytest

from hd_prognostic.models import ArchardWear, ExponentialFade, ParisCrack
from hd_prognostic.observation import ObservationModel
from hd_prognostic.pf import ParticleFilter, log_likelihood, resample, weighted_quantile
from hd_prognostic.rul import rul_distribution
from hd_prognostic.ukf import UnscentedKalmanFilter


def _obs():
    return ObservationModel(coef=[1e-5, 3e-5], s0=1e-6, s1=1e-6, h_ref=1e-5)


def _model(**kw):
    return ArchardWear(h_fail=30e-6, log_kappa_mean=np.log(1e-12), log_kappa_std=0.5, observe_fn=_obs(), **kw)


def _truth(model, n, W, seed):
    rng = np.random.default_rng(seed)
    x = model.sample_prior(1, rng)
    xs = [x]
    for _ in range(n):
        x = model.propagate(x, W, rng)
        xs.append(x)
    X = np.vstack(xs)
    obs = model.observe_fn
    z = obs.mean(X[:, 0]) + obs.std(X[:, 0]) * rng.standard_normal(len(X))
    return X, z


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual", "multinomial"])
def test_resampling_preserves_expected_counts(scheme):
    rng = np.random.default_rng(3)
    w = rng.random(50) ** 3
    w /= w.sum()
    counts = np.zeros(50)
    reps = 400
    for _ in range(reps):
        counts += np.bincount(resample(w, rng, scheme), minlength=50)
    mean_counts = counts / reps
    # E[count_i] = n w_i for every unbiased scheme
    assert np.allclose(mean_counts, 50 * w, atol=0.35)
    idx = resample(w, rng, scheme)
    c = np.bincount(idx, minlength=50)
    assert c.sum() == 50
    if scheme == "systematic":  # every count within 1 of n w_i
        assert np.all(np.abs(c - 50 * w) < 1.0 + 1e-9)
    if scheme == "residual":  # the deterministic copies are always there
        assert np.all(c >= np.floor(50 * w))


def test_pf_converges_to_truth_and_learns_parameter():
    model = _model()
    X, z = _truth(model, 60, 1e5, seed=7)
    pf = ParticleFilter(model, 3000, seed=0)
    for k in range(1, len(z)):
        pf.step(1e5, z[k])
    m, s = pf.mean(), pf.std()
    assert abs(m[0] - X[-1, 0]) < 3 * s[0] + 1e-7
    assert s[0] < 0.2 * X[-1, 0]
    # the wear coefficient is learned: posterior is narrower than the prior and covers the truth
    assert s[1] < 0.5 * model.log_kappa_std
    assert abs(m[1] - X[-1, 1]) < 3 * s[1] + 0.05


def test_pf_is_seedable():
    model = _model()
    _, z = _truth(model, 10, 1e5, seed=1)
    a, b = ParticleFilter(model, 500, seed=4), ParticleFilter(model, 500, seed=4)
    for k in range(1, len(z)):
        a.step(1e5, z[k])
        b.step(1e5, z[k])
    assert np.array_equal(a.x, b.x)


def test_nan_observation_is_predict_only():
    model = _model()
    pf = ParticleFilter(model, 1000, seed=0)
    w0 = pf.weights.copy()
    info = pf.step(1e5, float("nan"))
    assert not info.observed and not info.resampled
    assert np.array_equal(pf.weights, w0)
    info = pf.step(1e5, None)
    assert not info.observed
    # the state still moved forward (prediction happened)
    assert pf.mean()[0] > 0


def test_student_t_is_robust_to_outlier():
    model = _model()
    X, z = _truth(model, 40, 1e5, seed=2)
    zz = z.copy()
    zz[30] = zz[30] + 50 * _obs().std(X[30, 0])  # gross outlier
    res = {}
    for kind in ("gaussian", "student_t"):
        pf = ParticleFilter(model, 3000, seed=0, likelihood=kind)
        for k in range(1, 31):
            pf.step(1e5, zz[k])
        res[kind] = abs(pf.mean()[0] - X[30, 0])
    assert res["student_t"] < res["gaussian"]


def test_log_likelihood_student_t_normalised():
    x = np.linspace(-200, 200, 400001)
    p = np.exp(log_likelihood(0.0, x, np.full_like(x, 1.3), "student_t", 4.0))
    assert abs(np.trapezoid(p, x) - 1) < 1e-3


def test_bad_filter_arguments_are_refused():
    with pytest.raises(ValueError, match="resampling"):
        ParticleFilter(_model(), 10, resampling="bogus")
    with pytest.raises(ValueError, match="ess_threshold"):
        ParticleFilter(_model(), 10, ess_threshold=0)
    with pytest.raises(ValueError, match="h_fail"):
        ArchardWear(h_fail=-1)
    with pytest.raises(ValueError, match="W must be finite"):
        _model().propagate(np.zeros((3, 2)), np.nan, None)


def test_rul_analytic_deterministic_growth():
    # no noise: h grows by kappa W = 1 um per step from h0; threshold 30 um -> RUL = ceil((30 - h0)/1)
    m = ArchardWear(h_fail=30e-6, sigma_proc=1e-12, sigma_log_kappa=0.0)
    h0 = np.array([0.0, 10.5e-6, 29.5e-6, 31e-6])
    x = np.column_stack([h0, np.full(4, np.log(1e-11))])
    r = rul_distribution(m, x, None, 1e5, 1.0, 100, rng=0)
    assert np.allclose(r.samples, [30, 20, 1, 0])


def test_rul_percentiles_gamma_case():
    # kappa W eps with lognormal eps: sum of n increments; compare with Monte Carlo of the same law
    # and with the analytic median for zero process noise over a lognormal kappa population:
    # RUL = ceil(H / (kappa W)) -> P50 at kappa = exp(mu)
    m = ArchardWear(h_fail=20e-6, sigma_proc=1e-9, sigma_log_kappa=0.0)
    rng = np.random.default_rng(0)
    mu, sd = np.log(1e-11), 0.3
    lk = mu + sd * rng.standard_normal(20000)
    x = np.column_stack([np.zeros(20000), lk])
    r = rul_distribution(m, x, None, 1e5, 1.0, 500, rng=1)
    # analytic: RUL = ceil(20 / (1e6 kappa W)) ; quantile q of RUL = ceil(20 / exp(mu + sd z_{1-q}) / 1e-11 * 1e-6 ...)
    from scipy.stats import norm

    for q, est in ((0.05, r.p5), (0.5, r.p50), (0.95, r.p95)):
        kap = np.exp(mu + sd * norm.ppf(1 - q))
        expect = np.ceil(20e-6 / (kap * 1e5))
        assert abs(est - expect) <= 1.0
    # risk curve is a CDF
    t = np.arange(0, r.samples.max() + 2)
    rk = r.risk(t)
    assert np.all(np.diff(rk) >= 0) and rk[0] == 0 and abs(rk[-1] - 1) < 1e-9


def test_weighted_quantile_matches_unweighted():
    v = np.random.default_rng(0).normal(size=20001)
    assert abs(weighted_quantile(v, np.ones_like(v), 0.5)[0] - np.median(v)) < 1e-3


def test_ukf_tracks_truth():
    model = _model()
    X, z = _truth(model, 50, 1e5, seed=5)
    u = UnscentedKalmanFilter.from_prior(model)
    for k in range(1, len(z)):
        u.step(1e5, z[k])
    assert abs(u.x[0] - X[-1, 0]) < 0.25 * X[-1, 0]
    u.update(float("nan"))  # predict-only is a no-op update


def test_other_models_run_in_the_same_filter():
    rng = np.random.default_rng(0)
    fade = ExponentialFade(C_eol=1.4, C0_mean=2.0, b_mean=-3e-3, b_std=1e-3, sigma_obs=0.01)
    c = 2.0 * np.exp(-3e-3 * np.arange(100)) + 0.01 * rng.standard_normal(100)
    pf = ParticleFilter(fade, 2000, seed=0)
    for k in range(1, 100):
        pf.step(1.0, c[k])
    assert abs(pf.mean()[1] + 3e-3) < 1e-3
    r = rul_distribution(fade, pf.x, pf.weights, 1.0, 1.0, 500, rng=0)
    true_rul = np.log(1.4 / 2.0) / -3e-3 - 99
    assert r.p5 <= true_rul + 3 and r.p95 >= true_rul - 3
    paris = ParisCrack(m=3.0, logC_mean=np.log(1e-9), a0_mean=9e-3)
    x = paris.sample_prior(100, rng)
    x2 = paris.propagate(x, 1000.0, None)
    assert np.all(x2[:, 0] > x[:, 0])
    # exact integration is step-size independent
    x3 = paris.propagate(paris.propagate(x, 500.0, None), 500.0, None)
    assert np.allclose(x2[:, 0], x3[:, 0], rtol=1e-10)


def test_offset_state_learns_unit_offset_and_wear():
    """A unit whose feature offset is 2 prior-sigmas from the population: the Rao-Blackwellised offset
    converges to it and the wear is tracked without the bias a fixed baseline would leave."""
    from hd_prognostic.models import ArchardWear

    obs = ObservationModel(coef=[0.0, 3e-5, 0.5e-5], s0=1.5e-6, s1=1e-6, h_ref=1e-5, baseline="state",
                           offset_mean=1e-5, offset_std=2e-6)
    model = ArchardWear(h_fail=30e-6, log_kappa_mean=np.log(1e-12), log_kappa_std=0.3, sigma_proc=0.05, h0_std=1e-8,
                        sigma_log_kappa=0.003, observe_fn=obs, offset_mean=obs.offset_mean,
                        offset_std=obs.offset_std, kappa_lifetime=True)
    assert model.state_names == ("h", "log_kappa", "b", "P_b") and model.n_marginalised == 2
    rng = np.random.default_rng(3)
    b_true, W, n = 1.4e-5, 1e5, 150
    h = np.cumsum(np.r_[0.0, np.full(n, 1.1e-12 * W)])
    z = b_true + obs.mean(h) + obs.std(h) * rng.standard_normal(len(h))
    pf = ParticleFilter(model, 2000, seed=1, likelihood="student_t", kernel="liu_west")
    for k in range(1, len(h)):
        pf.step(W, z[k])
    m = pf.mean()
    assert abs(m[2] - b_true) < 1.5e-6  # offset learned (prior mean was 2 sigma away)
    assert abs(m[0] - h[-1]) < 1.5e-6  # wear within 1.5 um at ~16 um
    assert np.all(pf.x[:, 3] > 0) and np.all(pf.x[:, 3] < obs.offset_std**2)  # posterior variance shrank
    # the UKF form of the same model: one plain static column
    mu = ArchardWear(h_fail=30e-6, observe_fn=obs, offset_mean=1e-5, offset_std=2e-6, offset_mode="state")
    assert mu.state_names == ("h", "log_kappa", "b")


def test_regeneration_likelihood_is_asymmetric():
    from hd_prognostic.models import ExponentialFade

    m = ExponentialFade(C_eol=1.4, sigma_obs=0.01, regen_nu=1.0)
    x = np.array([[1.80, -1e-3], [1.85, -1e-3]])
    ll_up = m.log_likelihood(1.85 + 0.05, x[:1] * [1, 1] + [0.05, 0])  # +5 sigma above
    ll_dn = m.log_likelihood(1.85 - 0.05, x[:1] * [1, 1] + [0.05, 0])  # -5 sigma below
    assert ll_up[0] > ll_dn[0] + 5  # an upward (regeneration) jump is far less surprising
    assert m.custom_likelihood and not ExponentialFade().custom_likelihood
    with pytest.raises(ValueError):
        ParticleFilter(m, 10, kernel="bogus")
