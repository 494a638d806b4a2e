"""Failure defined as the measured HI reaching a known level, at a recorded crossing time (Virkler: the cycle
count at which the crack length reached 49.8 mm, with no record between 39 mm and that length).

``failure_at="crossing"`` scores the failure time as the density of that crossing and compares the defined level
with a level fitted in the path's coordinates (AIC, training units only). A path family whose shape is wrong
between the last records and the level (a power law on crack growth) does not reach the defined level at the
failure times: the interval likelihood with the level fixed then leaves that bias to the level's scatter s_Y
(wide, late forecasts: the Virkler symptom), the crossing likelihood fits the level the path does reach."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory
from tests.prognostic.lifesynth import forecast_scores

A_F = 50.0  # failure length (the failure definition)


def crack_units(n: int, seed: int, a0: float = 9.0, m: float = 3.0, a_stop: float = 39.0, every: float = 10.0,
                noise: float = 0.2):
    """Crack length by Paris' law (dK ~ sqrt(a)) a(N) = a0 (1 - N/N_b)^(-2/(m-2)), per-unit log-normal N_b;
    records every ``every`` cycles up to ``a_stop``; failure at the exact cycle count where a reaches A_F."""
    rng = np.random.default_rng(seed)
    p = 2.0 / (m - 2.0)
    units, eol = [], {}
    for i in range(n):
        Nb = 300.0 * math.exp(rng.normal(0.0, 0.25))
        Nf = Nb * (1.0 - (a0 / A_F) ** (1.0 / p))
        t = np.arange(0.0, Nf, every)
        a = a0 * (1.0 - t / Nb) ** (-p)
        k = int(np.searchsorted(a, a_stop))
        u = f"C{i:02d}"
        units.append(UnitHistory(u, t[:k], a[:k] + rng.normal(0.0, noise, k), t[:k].copy(), discrete=False,
                                 events=UnitEvents(failure=float(Nf))))
        eol[u] = float(Nf)
    return units, eol


@pytest.fixture(scope="module")
def fleet():
    return crack_units(10, seed=1), crack_units(4, seed=9)


def test_crossing_fits_the_level_a_misfit_path_reaches(fleet):
    (units, _), (test, eol) = fleet
    iv = LifeModel.fit(units, threshold="observable", path="power", failure_level=A_F, n_draws=0)
    cr = LifeModel.fit(units, threshold="observable", path="power", failure_level=A_F, n_draws=0,
                       failure_at="crossing")
    # interval + fixed level: the power law's end falls short of A_F, the level scatter absorbs it (mm-wide)
    assert iv.theta["Y0"] == A_F and math.exp(iv.theta["log_sY"]) > 3.0
    # crossing: the fitted level wins by AIC, below the defined one (where the power law is at failure)
    la = cr.fit_info["level_aic"]
    assert cr.fit_info["level"] == "fitted" and la["fitted"] < la["fixed"] - 10.0
    assert 40.0 < cr.theta["Y0"] < A_F - 1.0 and math.exp(cr.theta["log_sY"]) < 1.0
    assert "failure_level" not in cr.fit_info and cr.fit_info["failure_at"] == "crossing"
    cov_i, inc_i, _ = forecast_scores(iv, test, eol)
    cov_c, inc_c, _ = forecast_scores(cr, test, eol)
    assert cov_i > 0.95 and inc_i < 0.6  # wide and biased late
    assert inc_c > inc_i + 0.3 and 0.7 < cov_c < cov_i
    m2 = LifeModel.from_json(cr.to_json())  # the model file keeps the crossing likelihood
    assert np.allclose(m2.log_marginal(units[:2]), cr.log_marginal(units[:2]))
    assert not np.allclose(LifeModel.from_json(dict(cr.to_json(), fit_info={"units": []})).log_marginal(units[:2]),
                           cr.log_marginal(units[:2]))


def test_crossing_keeps_the_defined_level_when_the_path_reaches_it(fleet):
    (units, _), _ = fleet
    m = LifeModel.fit(units, threshold="observable", path="paris", failure_level=A_F, n_draws=0,
                      failure_at="crossing")
    la = m.fit_info["level_aic"]
    assert m.fit_info["level"] == "fixed" and m.theta["Y0"] == A_F
    assert la["fitted"] > la["fixed"]  # nested fit (started at the fixed optimum): one parameter, < 1 gained
    assert la["fitted"] < la["fixed"] + 2.0 + 1e-6


def test_failure_at_is_checked(fleet):
    (units, _), _ = fleet
    with pytest.raises(ValueError, match="failure_at"):
        LifeModel.fit(units, failure_at="exact")
    with pytest.raises(ValueError, match="observable"):
        LifeModel.fit(units, threshold="latent", failure_at="crossing")
