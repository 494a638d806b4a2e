"""The coverage's unit-level uncertainty (metrics.coverage_interval) and the between-unit scales' prior of the
parameter draws (LifeModel.fit(scale_prior=...)); src/hd_prognostic/README.md, 'Over-coverage of a small fleet'."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel
from hd_prognostic.metrics import coverage_interval

from .lifesynth import synth_units


def test_coverage_interval_bootstrap_and_wilson():
    c = [1.0, 1.0, 1.0, 0.89, 1.0, 0.96]
    ci = coverage_interval(c, seed=0)
    assert ci["n_units"] == 6 and ci["coverage"] == pytest.approx(np.mean(c))
    assert ci["se"] == pytest.approx(np.std(c, ddof=1) / math.sqrt(6))
    lo, hi = ci["boot"]
    assert lo < ci["coverage"] < hi <= 1.0 and lo > 0.9  # resampled means of these six values
    # Wilson score interval of p = 0.975 with n = 6 trials (closed form at z = 1.96)
    p, n, z = ci["coverage"], 6, 1.959963984540054
    den = 1 + z * z / n
    mid, half = (p + z * z / (2 * n)) / den, z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    assert ci["wilson"] == pytest.approx([mid - half, mid + half])
    assert ci["consistent_boot"] and ci["consistent_wilson"]
    # every unit at 1.00: the bootstrap sees no spread (degenerate, not consistent); Wilson still is
    one = coverage_interval([1.0] * 6)
    assert one["boot"] == [1.0, 1.0] and not one["consistent_boot"] and one["consistent_wilson"]
    # a clearly low fleet is inconsistent with 0.85-0.95 by the bootstrap; NaN units are dropped
    low = coverage_interval([0.5, 0.55, 0.6, 0.62, 0.58, float("nan")])
    assert low["n_units"] == 5 and low["boot"][1] < 0.85 and not low["consistent_boot"]


@pytest.fixture(scope="module")
def fits():
    units, _ = synth_units(7, seed=5, censor_frac=0.0)
    kw = dict(n_draws=40, seed=0, threshold="latent", path="power")
    return LifeModel.fit(units, **kw), LifeModel.fit(units, scale_prior="log", **kw)


def test_log_scale_prior_narrows_the_between_unit_scales(fits):
    """Same data, same mode: 1/sd on s, s_a and s_D puts the draws' scales lower than the uniform prior (whose
    posterior of a normal scale from n groups has n - 2 dof instead of n - 1: wider predictive intervals)."""
    uni, log = fits
    assert log.fit_info["scale_prior"] == "log" and "scale_prior" not in uni.fit_info
    assert "1/sd on the between-unit scales" in log.fit_info["parameter_uncertainty"]["prior"]
    assert uni.theta == log.theta  # the maximum-likelihood point is the prior's business not
    for k in ("log_s", "log_sD"):
        mu_ = np.mean([math.exp(d["theta"][k]) for d in uni.draws])
        ml_ = np.mean([math.exp(d["theta"][k]) for d in log.draws])
        assert ml_ < mu_, k


def test_scale_prior_checked():
    units, _ = synth_units(4, seed=1, censor_frac=0.0)
    with pytest.raises(ValueError, match="scale_prior 'flat'"):
        LifeModel.fit(units, scale_prior="flat", n_draws=0)


# ---- the level noise's regularity guard (lifemodel._noise_regularity), on likelihoods of known shape
NAMES = ["mu", "log_sigma", "log_kappa", "atanh_rho"]


def _quad(x0, sd, bound_rho=3.0, ridge=False):
    """A negative log-likelihood: independent normal in each coordinate (or, ``ridge``, flat along log_sigma +
    log_kappa = const: the noise all proportional to L), infinite past |atanh rho| >= bound_rho."""
    x0, sd = np.asarray(x0, float), np.asarray(sd, float)

    def nll(x):
        if abs(x[3]) >= bound_rho:
            return 1e30
        r = (x - x0) / sd
        if ridge:  # only the sum sigma * kappa is determined
            r[1], r[2] = (x[1] + x[2] - x0[1] - x0[2]) / sd[1], 0.0
        return 0.5 * float(r @ r)
    return nll


def test_noise_regularity_interior_fit_is_regular():
    from hd_prognostic.lifemodel import _noise_regularity

    x0 = [0.1, -5.0, 1.0, 0.3]
    r = _noise_regularity(_quad(x0, [0.1, 0.05, 0.2, 0.05]), np.array(x0), NAMES)
    assert r["regular"], r
    assert r["wald"]["log_kappa"] == pytest.approx([1.0 - 1.96 * 0.2, 1.0 + 1.96 * 0.2], abs=2e-3)


def test_noise_regularity_rejects_a_bound_a_ridge_and_a_wald_interval_at_the_box():
    from hd_prognostic.lifemodel import _noise_regularity

    # rho at its bound (0.995): the optimum's neighbour is outside the parameter space
    x0 = [0.1, -5.0, 1.0, 2.999]
    r = _noise_regularity(_quad(x0, [0.1, 0.05, 0.2, 0.05]), np.array(x0), NAMES)
    assert not r["regular"] and "bound of atanh_rho" in r["reason"]
    # sigma -> 0 with kappa -> infinity: a flat direction of the noise parameters
    x0 = [0.1, -8.0, 4.0, 0.3]
    r = _noise_regularity(_quad(x0, [0.1, 0.05, 0.2, 0.05], ridge=True), np.array(x0), NAMES)
    assert not r["regular"] and "not positive definite" in r["reason"]
    # an interior optimum whose likelihood does not bound kappa away from its numerical limit (log kappa < 5)
    x0 = [0.1, -5.0, 4.5, 0.3]
    r = _noise_regularity(_quad(x0, [0.1, 0.05, 0.4, 0.05]), np.array(x0), NAMES)
    assert not r["regular"] and "log_kappa Wald" in r["reason"]
    # the same optimum with a sharp likelihood is regular: the rule is about the information, not the value
    assert _noise_regularity(_quad(x0, [0.1, 0.05, 0.1, 0.05]), np.array(x0), NAMES)["regular"]


def test_noise_regularity_ignores_a_flat_direction_of_the_other_parameters():
    """A threshold scatter at 0 (flat in its log: shared by the constant fit) is not the noise's flaw: the noise
    parameters' profile information is what the rule reads."""
    from hd_prognostic.lifemodel import _noise_regularity

    x0 = np.array([0.1, -5.0, 1.0, 0.3])

    def nll(x):
        r = (x - x0) / np.array([1.0, 0.05, 0.2, 0.05])
        r[0] = 0.0  # mu: flat
        return 0.5 * float(r @ r)
    assert _noise_regularity(nll, x0, NAMES)["regular"]
