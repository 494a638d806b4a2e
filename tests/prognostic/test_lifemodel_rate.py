"""How the prognosis extrapolates a unit's exposure: the mean (default) or the median per-step rate of its record
(``UnitHistory.rate``, ``LifeModel.fit(exposure_rate=...)``, bench ``--exposure-rate``). Right-skewed per-mission
exposure (load work) puts the median below the mean; the failure exposure is then reached later with the median."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel, UnitHistory
from tests.prognostic.lifesynth import synth_units


def test_rate_estimators_on_skewed_increments():
    rng = np.random.default_rng(0)
    dE = rng.lognormal(0.0, 0.5, 400)  # right-skewed per-step exposure: mean exp(0.125) ~ 1.13 x the median 1
    t = np.arange(401.0)
    t[200:] += 3.0  # a gap of 3 steps with its exposure in one increment: time-weighted in both estimators
    E = np.concatenate([[0.0], np.cumsum(dE)])
    u = UnitHistory("U", t, np.zeros(401), E)
    assert u.rate("mean") == pytest.approx(E[-1] / t[-1])
    assert u.rate() == u.rate("median") == pytest.approx(float(np.median(dE[np.diff(t) > 0] / np.diff(t))))
    assert u.rate("mean") / u.rate("median") == pytest.approx(math.exp(0.125), rel=0.08)
    with pytest.raises(ValueError, match="median, mean"):
        u.rate("mode")


def test_fit_keeps_the_estimator_and_the_prognosis_uses_it():
    units, _ = synth_units(8, seed=3, censor_frac=0.0)
    # the rate alone (no renewal spread of the future exposure: tests/prognostic/test_lifemodel_spread.py)
    m = LifeModel.fit(units, n_draws=0, maxiter=100, exposure_rate="median", exposure_spread="none")
    assert m.fit_info["exposure_rate"] == "median"
    mm = LifeModel.fit(units, n_draws=0, maxiter=100, exposure_spread="none")  # default: the mean
    assert mm.fit_info["exposure_rate"] == "mean" and mm.theta == m.theta  # the fit itself is the same
    assert LifeModel.from_json(mm.to_json()).fit_info["exposure_rate"] == "mean"
    # a model saved before the key existed keeps the median it was scored with
    d = json.loads(json.dumps(mm.to_json()))
    del d["fit_info"]["exposure_rate"]
    old = LifeModel.from_json(d)
    with pytest.raises(ValueError, match="exposure_rate"):
        LifeModel.fit(units, n_draws=0, exposure_rate="mode")
    # a unit flying right-skewed missions: two big missions among small ones (mean 1.5x the median)
    u = units[0].truncated(20.0)
    dE = np.ones(20)
    dE[[4, 13]] = 6.0
    u.E = np.concatenate([[0.0], np.cumsum(dE)])
    u.E_next = float(u.E[-1] + 1.0)
    z = np.zeros(400)
    r_med = m.rul_samples(z, u, 20.0, np.random.default_rng(2))
    r_mean = mm.rul_samples(z, u, 20.0, np.random.default_rng(2))
    assert np.array_equal(old.rul_samples(z, u, 20.0, np.random.default_rng(2)), r_med)
    ratio = (np.median(r_mean) - 1.0) / (np.median(r_med) - 1.0)  # steps after the known next one
    assert ratio == pytest.approx(u.rate("median") / u.rate("mean"), rel=0.05)
    assert u.rate("mean") / u.rate("median") == pytest.approx(1.5)
