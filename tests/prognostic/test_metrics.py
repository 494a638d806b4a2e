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
    assert M.prognostic_horizon(t, 50.0, r_hat=r_hat, alpha=0.1, form="sustained") == 30.0
    # inside at once, last prediction out: first entry 50 (Saxena, progpy), sustained 0
    late_miss = r_true + np.array([0, 0, 0, 0, 9])
    assert M.prognostic_horizon(t, 50.0, r_hat=late_miss, alpha=0.1) == 50.0
    assert M.prognostic_horizon(t, 50.0, r_hat=late_miss, alpha=0.1, form="sustained") == 0.0
    # closed band in the default convention, open in progpy's; never met: 0 vs None
    edge = r_true + 5.0
    assert M.prognostic_horizon(t, 50.0, r_hat=edge, alpha=0.1) == 50.0
    assert M.prognostic_horizon(t, 50.0, r_hat=edge, alpha=0.1, convention="progpy") is None
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


# ---------------------------------------------------------------- issue 17 ---

def test_finite_medians_are_never_clipped():
    # issue 17, item 1: a finite median of 100 at true RUL 10 is an error of 90, not of 2 t_eol + 1 - 10
    m = M.score_history([0, 1, 2], [100, 8, 7], [50, 6, 5], [150, 10, 9], 10)
    assert m["cra"] == pytest.approx(np.mean([1 - 90 / 10, 1 - 1 / 9, 1 - 1 / 8]))  # -2.079
    assert m["mae"] == pytest.approx(92 / 3)
    assert m["n_inf_capped"] == 0


def test_one_cap_for_infinite_medians_p95_and_samples():
    # a forecast that never fails within its horizon H is scored as RUL = max(H, r*(t_p)): the smallest value it
    # asserts, never below the longest true RUL scored; the same cap for P50, P5/P95 and the CRPS samples
    t, eol = np.array([0, 1, 2.0]), 10.0
    s = [np.array([5, 9, np.inf, np.inf]), np.array([7, 8, 9, 10.0]), np.array([6, 7, 8, 9.0])]
    m = M.score_history(t, [np.inf, 8, 7], [5, 7, 6], [np.inf, 10, 9], eol, samples=s, rul_horizon=50.0)
    assert m["inf_cap"] == 50.0 and m["n_inf_capped"] == 4 and "horizon" in m["inf_cap_rule"]
    assert m["mae"] == pytest.approx((40 + 1 + 1) / 3)
    capped = [np.array([5, 9, 50, 50.0]), s[1], s[2]]
    assert m["crps_mean"] == pytest.approx(np.mean([M.crps(c, r) for c, r in zip(capped, eol - t)]))
    assert m["coverage_p5_p95"] == 1.0
    # horizon shorter than the first true RUL: the cap is r*(t_p), never an under-prediction of it
    assert M.score_history(t, [np.inf, 8, 7], [5, 7, 6], [np.inf, 10, 9], eol, rul_horizon=4.0)["inf_cap"] == 10.0
    # horizon unknown: the largest finite RUL of the history stands for it (all finite values stay below the cap)
    m2 = M.score_history(t, [np.inf, 8, 7], [5, 7, 6], [np.inf, 30, 9], eol)
    assert m2["inf_cap"] == 30.0 and "largest finite" in m2["inf_cap_rule"]


def test_ph_point_and_ph_beta_are_named_separately():
    # issue 17, item 2: the median is inside the band from t = 0, the distribution's mass only from t = 20
    t = np.arange(0, 50, 10.0)
    eol = 50.0
    rt = eol - t
    p50 = rt.copy()
    s = [np.array([r, r + 40, r + 40, r + 40]) if r > 30 else np.array([r, r, r, r + 40]) for r in rt]
    m = M.score_history(t, p50, p50 - 1, p50 + 1, eol, samples=s, alpha_ph=0.1, beta=0.5)
    assert "prognostic_horizon" not in m
    assert m["ph_point"] == 50.0 and m["ph_beta"] == 30.0
    assert M.score_history(t, p50, p50 - 1, p50 + 1, eol, alpha_ph=0.1)["ph_point"] == 50.0
    assert "ph_beta" not in M.score_history(t, p50, p50 - 1, p50 + 1, eol, alpha_ph=0.1)


def test_quantile_grid_is_symmetric_and_unbiased():
    # issue 17, item 3: the stored grid 0.01..0.97 gave means 2-3 % low and PIT +0.01 on calibrated forecasts
    from scipy import stats

    from hd_prognostic.tracking import QUANTILE_LEVELS, RULHistory

    q = np.asarray(QUANTILE_LEVELS)
    assert q[0] == pytest.approx(0.01) and q[-1] == pytest.approx(0.99)
    assert np.allclose(q + q[::-1], 1.0)
    dist = stats.lognorm(s=0.4, scale=60.0)
    samples = dist.ppf((np.arange(20000) + 0.5) / 20000)  # the distribution itself, to 1/20000
    h = RULHistory(unit="u", time_unit="step", rul_t=[0.0], p5=[1.0], p50=[2.0], p95=[3.0], samples=[samples])
    h2 = RULHistory.from_json(h.to_json())
    assert h2.to_json()["rul_quantile_levels"] == pytest.approx(list(q))
    w = h2.sample_weights[0] if h2.sample_weights else np.full(len(h2.samples[0]), 1 / len(h2.samples[0]))
    mean = np.sum(np.asarray(w) * h2.samples[0]) / np.sum(w)
    assert abs(mean / dist.mean() - 1) < 0.006
    u = np.linspace(0.02, 0.98, 481)
    bias = np.mean([M.pit(h2.samples[0], dist.ppf(x), w) - x for x in u])
    assert abs(bias) < 0.002
    # a history written with the old grid (0.01..0.97) is read with cell weights: PIT unbiased there too
    old = h.to_json()
    lv = np.linspace(0.01, 0.97, 49)
    old["rul_quantile_levels"] = lv.tolist()
    old["rul_quantiles"] = [dist.ppf(lv).tolist()]
    h3 = RULHistory.from_json(old)
    assert np.sum(h3.sample_weights[0]) == pytest.approx(1.0)
    bias3 = np.mean([M.pit(h3.samples[0], dist.ppf(x), h3.sample_weights[0]) - x for x in u])
    assert abs(bias3) < 0.002


def test_one_rule_for_the_prediction_at_t_lambda():
    # issue 17, item 4: t_lambda = 25 lies between predictions at 20 and 30; default rule: the latest prediction
    # at or before t_lambda, aged to it, for alpha-lambda and RA alike; progpy's: the first at or after, unaged
    t = np.array([0, 10, 20, 30, 40.0])
    eol = 50.0
    p50 = np.array([50, 40, 33, 12, 10.0])  # aged 20 -> 25: 28 vs r* 25 (in the 20 % cone); at 30: 12 vs 20 (out)
    m = M.score_history(t, p50, p50 - 1, p50 + 1, eol, lambdas=(0.5,))
    assert m["alpha_lambda_point"] == {"0.5": True}
    assert m["relative_accuracy_lambda_0.5"] == pytest.approx(1 - 3 / 25)
    p = M.score_history(t, p50, p50 - 1, p50 + 1, eol, lambdas=(0.5,), convention="progpy")
    assert p["alpha_lambda_point"] == {"0.5": False}
    assert p["relative_accuracy_lambda_0.5"] == pytest.approx(1 - abs(50 - (30 + 12)) / 50)  # progpy: RA of the ToE


def _histories(seed=0):
    """Three RUL histories with samples: biased, calibrated-ish and late-converging, t_p = first prediction."""
    rng = np.random.default_rng(seed)
    out = []
    for k, (eol, bias, spread) in enumerate([(41.3, 0.4, 0.25), (63.7, 0.0, 0.3), (30.2, -0.5, 0.1)]):
        t = np.arange(2.0 * k, eol, 1.5)
        rt = eol - t
        conv = np.linspace(1, 0, len(t))  # bias shrinks towards the end of life
        s = [np.maximum(r * (1 + bias * c + spread * rng.standard_normal(300)), 0.01) for r, c in zip(rt, conv)]
        p = np.array([np.quantile(x, [0.05, 0.5, 0.95]) for x in s])
        out.append((t, p[:, 1], p[:, 0], p[:, 2], eol, s))
    return out


def test_oracle_progpy_metrics():
    """alpha-lambda (beta), PH (first entry), RA at lambda and CRA equal progpy's in its convention."""
    pytest.importorskip("progpy")
    from progpy.predictors import ToEPredictionProfile
    from progpy.uncertain_data import ScalarData, UnweightedSamples

    lambdas, alpha, beta, alpha_ph = (0.25, 0.5, 0.75), 0.2, 0.5, 0.1
    for t, p50, p5, p95, eol, s in _histories():
        m = M.score_history(t, p50, p5, p95, eol, samples=s, alpha=alpha, lambdas=lambdas, alpha_ph=alpha_ph,
                            beta=beta, convention="progpy")
        assert m["convention"] == "progpy" and m["cone"] == "open"
        prof, prof_pt = ToEPredictionProfile(), ToEPredictionProfile()
        for ti, x, med in zip(t, s, p50):
            prof.add_prediction(ti, UnweightedSamples([{"EOL": ti + v} for v in x]))
            prof_pt.add_prediction(ti, ScalarData({"EOL": ti + med}))
        gt = {"EOL": eol}
        t_p = t[0]
        for lam in lambdas:
            tl = t_p + lam * (eol - t_p)
            assert m["alpha_lambda_beta"][str(lam)] == prof.alpha_lambda(gt, tl, alpha, beta)["EOL"]
            assert m["alpha_lambda_point"][str(lam)] == prof_pt.alpha_lambda(gt, tl, alpha, 1.0)["EOL"]
        tl = t_p + 0.5 * (eol - t_p)
        first_after = next(ti for ti in prof.keys() if ti >= tl)
        assert m["relative_accuracy_lambda_0.5"] == pytest.approx(
            prof[first_after].relative_accuracy(gt)["EOL"], rel=1e-12, abs=1e-12)
        assert m["cra"] == pytest.approx(prof.cumulative_relative_accuracy(gt)["EOL"], rel=1e-12, abs=1e-12)

        def crit(tte, gt_tte):
            b = {k: [g - alpha_ph * eol, g + alpha_ph * eol] for k, g in gt_tte.items()}
            return {k: v >= beta for k, v in tte.percentage_in_bounds(b).items()}

        ph = prof.prognostic_horizon(crit, gt)["EOL"]
        ph_pt = prof_pt.prognostic_horizon(crit, gt)["EOL"]
        assert (m["ph_beta"] is None and ph is None) or m["ph_beta"] == pytest.approx(ph, rel=1e-12)
        assert (m["ph_point"] is None and ph_pt is None) or m["ph_point"] == pytest.approx(ph_pt, rel=1e-12)
    # the histories exercise both outcomes (a test that always passes or always fails proves nothing)
    res = [M.score_history(*h[:5], samples=h[5], convention="progpy") for h in _histories()]
    passes = [v for r in res for v in r["alpha_lambda_beta"].values()]
    assert any(passes) and not all(passes)


def test_crps_and_pit_equal_a_direct_computation_from_samples():
    from scipy import stats

    for t, p50, p5, p95, eol, s in _histories(1):
        m = M.score_history(t, p50, p5, p95, eol, samples=s)
        rt = eol - t
        direct_crps = [np.mean(np.abs(x - r)) - 0.5 * np.mean(np.abs(x[:, None] - x[None, :]))
                       for x, r in zip(s, rt)]
        direct_pit = [np.mean(x < r) + 0.5 * np.mean(x == r) for x, r in zip(s, rt)]
        assert m["crps_mean"] == pytest.approx(np.mean(direct_crps), rel=1e-12)
        assert m["pit"] == pytest.approx(direct_pit, abs=1e-15)
        # = progpy's calc_metrics "ground truth percentile" / 100 (scipy percentileofscore, ties split alike)
        assert m["pit"] == pytest.approx([stats.percentileofscore(x, r) / 100 for x, r in zip(s, rt)], abs=1e-12)
    # ties split at the midpoint (discrete RUL steps)
    assert M.score_history([0.0], [2.0], [1.0], [3.0], 2.0, samples=[np.array([1, 2, 2, 3.0])])["pit"] == [0.5]


def test_aggregate_reads_old_reports_and_refuses_mixed_conventions():
    old = {"alpha_lambda": {"0.5": True}, "prognostic_horizon": 12.0, "cra": 0.5, "pit_ks": 0.1}
    a = M.aggregate([old])
    assert a["alpha_lambda_point_pass_rate"] == {"0.5": 1.0} and a["ph_beta_sustained"] == 12.0
    t, p50, p5, p95, eol, s = _histories()[0]
    with pytest.raises(ValueError, match="convention"):
        M.aggregate([M.score_history(t, p50, p5, p95, eol),
                     M.score_history(t, p50, p5, p95, eol, convention="progpy")])
