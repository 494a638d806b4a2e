"""The future exposure's variability in the prognosis (``LifeModel.fit(exposure_spread="renewal")``, the default;
bench ``--exposure-spread``): the time to accrue the remaining exposure is the first passage of the renewal process
of the unit's i.i.d. per-step increments (inverse Gaussian, mean D / m, var D v / m^3). Constant increments (and an
exposure that is the time column) leave the RUL samples unchanged, bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel, UnitHistory

THETA = {"mu": 0.0, "log_s": np.log(0.3), "log_b": np.log(2.0), "c": 1.0, "a0": 0.0, "log_sa": np.log(0.1),
         "log_sigma": np.log(0.05), "log_sD": np.log(0.1), "atanh_rho": 0.0}


def _models():
    ren = LifeModel(THETA, E_ref=140.0, fit_info={"exposure_rate": "mean", "exposure_spread": "renewal"})
    none = LifeModel(THETA, E_ref=140.0, fit_info={"exposure_rate": "mean", "exposure_spread": "none"})
    return ren, none


def _unit(dE, discrete=True, t=None):
    t = np.arange(len(dE) + 1.0) if t is None else t
    E = np.concatenate([[0.0], np.cumsum(dE)])
    return UnitHistory("U", t, np.zeros(len(t)), E, discrete=discrete)


def test_rate_var():
    assert _unit(np.full(30, 1.7)).rate_var() == 0.0
    dE = np.tile([0.7, 1.3], 20)
    assert _unit(dE).rate_var() == pytest.approx(np.var(dE, ddof=1))
    # exposure = time on an irregular continuous clock: no spread
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.5, 3.0, 30)])
    assert _unit(np.diff(t), discrete=False, t=t).rate_var() == 0.0
    assert _unit(np.array([2.0])).rate_var() == 0.0  # one increment: no variance


def test_constant_increments_unchanged():
    ren, none = _models()
    z = np.random.default_rng(1).normal(0.0, 0.3, 3000)
    for u in (_unit(np.full(40, 1.0)), _unit(np.full(40, 2.5), discrete=False)):
        h = u.truncated(30.0)
        a = ren.rul_samples(z, u, 30.0, np.random.default_rng(5), h=h)
        b = none.rul_samples(z, u, 30.0, np.random.default_rng(5), h=h)
        assert np.array_equal(a, b)
    # a model saved without the key: no spread
    d = json.loads(json.dumps(ren.to_json()))
    del d["fit_info"]["exposure_spread"]
    u = _unit(np.tile([0.7, 1.3], 20))
    old = LifeModel.from_json(d)
    assert np.array_equal(old.rul_samples(z, u, 40.0, np.random.default_rng(5)),
                          none.rul_samples(z, u, 40.0, np.random.default_rng(5)))
    with pytest.raises(ValueError, match="exposure_spread"):
        LifeModel.fit([u], exposure_spread="bootstrap")


def test_variable_increments_spread_grows_as_renewal():
    ren, none = _models()
    inc = np.tile([0.7, 1.3], 20)  # mean 1, per-step variance 0.09 (x 40/39 sample)
    u = _unit(inc)
    u.E_next = float(u.E[-1] + 1.0)
    n = 20000
    z = np.zeros(n)
    a = ren.rul_samples(z, u, 40.0, np.random.default_rng(7))
    b = none.rul_samples(z, u, 40.0, np.random.default_rng(7))  # same failure exposures (same stream before)
    m, v = u.rate("mean"), u.rate_var()
    D = (b - 1.0) * m  # ~ remaining exposure after the known next step (to the step's rounding)
    expected = float(np.mean(D)) * v / m ** 3
    assert 5.0 < expected < 15.0  # a non-trivial spread next to var(b) ~ 50
    assert np.mean(a) == pytest.approx(np.mean(b), abs=0.3)  # no bias: the mean passage time is D / m
    assert np.var(a - b) == pytest.approx(expected, rel=0.1)
    assert np.var(a) - np.var(b) == pytest.approx(expected, rel=0.15)
    # against the renewal process itself: future increments resampled i.i.d. from the unit's own
    rng = np.random.default_rng(8)
    Ef = (b - 1.0) * m + u.E_next  # the failure exposures to within a step
    S = u.E_next + np.cumsum(rng.choice(inc, size=(n, 200)), axis=1)
    N = 1.0 + np.argmax(S >= Ef[:, None], axis=1) + 1.0 * (Ef > u.E_next)
    N[Ef <= u.E_next] = 1.0
    assert np.std(a) == pytest.approx(np.std(N), rel=0.05)
