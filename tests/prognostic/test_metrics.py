"""PHM metrics against hand-computed examples."""

import numpy as np
import pytest

from hd_prognostic import metrics as M


def test_alpha_cone_and_alpha_lambda_by_hand():
    # EOL 100, predictions at t = 0, 20, 40, 60, 80 (true RUL 100, 80, 60, 40, 20)
    t = np.array([0, 20, 40, 60, 80.0])
    r_hat = np.array([130, 90, 70, 41, 30.0])
    # cone alpha = 0.2: [80,120], [64,96], [48,72], [32,48], [16,24]
    assert M.in_alpha_cone(r_hat, 100 - t, 0.2).tolist() == [False, True, True, True, False]
    al = M.alpha_lambda(t, r_hat, 100.0, 0.0, 0.2, lambdas=(0.2, 0.5, 0.8))
    # lambda 0.2 -> t = 20 (pred 90 vs 80: in); 0.5 -> t = 50 uses the t = 40 prediction aged 10: 60 vs 50 in [40, 60]: in
    # 0.8 -> t = 80: 30 vs 20 -> out
    assert al == {0.2: True, 0.5: True, 0.8: False}
    # lambda >= 0.5: t = 60, 80 -> 1 of 2 inside
    assert M.fraction_in_cone(t, r_hat, 100.0, 0.0, 0.2, 0.5) == 0.5


def test_relative_accuracy_and_cra_by_hand():
    assert M.relative_accuracy(90, 100)[0] == pytest.approx(0.9)
    assert M.relative_accuracy(120, 100)[0] == pytest.approx(0.8)
    t = np.array([0, 50.0])
    # RA = 1 - 10/100 = 0.9 ; 1 - 25/50 = 0.5 ; CRA mean = 0.7
    assert M.cumulative_relative_accuracy(t, [110, 25], 100.0) == pytest.approx(0.7)


def test_convergence_by_hand():
    # constant error 2 from t=0 to 10 (last point not integrated): centroid (5, 1) -> distance sqrt(26)
    t = np.array([0, 5, 10.0])
    assert M.convergence(t, [2, 2, 2], 0.0) == pytest.approx(np.sqrt(26))
    # error that vanishes faster converges better (smaller)
    assert M.convergence(t, [2, 0, 0]) < M.convergence(t, [2, 2, 0])


def test_prognostic_horizon_by_hand():
    t = np.array([0, 10, 20, 30, 40.0])
    r_true = 50 - t
    # band alpha_ph = 0.1 * 50 = 5: first two out, then inside until the end
    r_hat = r_true + np.array([10, -7, 3, 4, -1])
    assert M.prognostic_horizon(t, 50.0, r_hat=r_hat, alpha=0.1) == 30.0
    # last prediction out -> PH 0
    assert M.prognostic_horizon(t, 50.0, r_hat=r_true + np.array([0, 0, 0, 0, 9]), alpha=0.1) == 0.0
    # probabilistic: beta mass inside the band
    s = [np.array([r - 1, r + 1, r + 20]) for r in r_true]  # 2/3 of the mass inside
    assert M.prognostic_horizon(t, 50.0, samples=s, alpha=0.1, beta=0.5) == 50.0
    assert M.prognostic_horizon(t, 50.0, samples=s, alpha=0.1, beta=0.9) == 0.0


def test_coverage_pit_crps_by_hand():
    assert M.coverage([0, 0, 5], [10, 10, 6], [5, 11, 5.5]) == pytest.approx(2 / 3)
    s = np.array([1.0, 2.0, 3.0, 4.0])
    assert M.pit(s, 2.5) == 0.5
    assert M.pit(s, 2.0) == pytest.approx(0.25 + 0.125)
    # CRPS of a point forecast is the absolute error
    assert M.crps(np.array([3.0]), 5.0) == pytest.approx(2.0)
    # two-point {0, 2} at y = 1: E|X-y| = 1, E|X-X'| = 1 -> 0.5
    assert M.crps(np.array([0.0, 2.0]), 1.0) == pytest.approx(0.5)
    # weighted form equals the repeated-sample form
    assert M.crps(np.array([0.0, 2.0]), 1.5, weights=[1, 3]) == pytest.approx(M.crps(np.array([0, 2, 2, 2.0]), 1.5))
    # CRPS of N(0,1) samples at 0 ~ (sqrt(2) - 1)/sqrt(pi)
    z = np.random.default_rng(0).standard_normal(200000)
    assert M.crps(z, 0.0) == pytest.approx((np.sqrt(2) - 1) / np.sqrt(np.pi), abs=3e-3)


def test_calibration_error():
    assert M.calibration_error(np.linspace(0.05, 0.95, 10)) == pytest.approx(0.05)
    assert M.calibration_error([0.99] * 10) > 0.9


def test_score_history_runs_and_excludes_after_eol():
    t = np.arange(0, 12.0)
    m = M.score_history(t, 10 - t, 8 - t, 12 - t, 10.0)
    assert m["n_predictions"] == 10
    assert m["frac_in_cone_lambda_ge_0.5"] == 1.0
    assert m["coverage_p5_p95"] == 1.0
    agg = M.aggregate([m, m])
    assert agg["n_units"] == 2 and agg["cra"] == pytest.approx(1.0)
