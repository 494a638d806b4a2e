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
    mid, half = (p + z * z / (2 * n)) / (1 + z * z / n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
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
