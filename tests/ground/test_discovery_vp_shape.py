"""The Stribeck shape's uncertainty by variable projection on the cross-validated residuals (issue 10).

``hd_twin.identify.vp_shape``: least-squares refinement of the shape (omega_s, delta, transition width eps)
on the leave-one-block-out residual vector, block-robust sandwich standard errors from its Jacobian, and a
weak-identification flag. Synthetic plants written here (numpy only, no hd_sim): a friction curve sampled
over its whole speed range (the shape must be recovered within its reported uncertainty) and the same
curve measured only below omega_s / 4 and above 4 omega_s (the gap a constant-speed mission can sit in: the
shape must come with a wide uncertainty, not as a confident number).
"""

import numpy as np
import pytest

from hd_twin.identify import Shape, cv_residuals, fit_separable, vp_shape

from .synthetic import stribeck_design

T_C, DT, W_S, DELTA, EPS, B = 1.0, 1.2, 4.0, 1.5, 0.8, 0.01
N_BLOCKS = 12


def _friction(w):
    return (T_C + DT * np.exp(-(np.abs(w) / W_S) ** DELTA)) * np.tanh(w / EPS) + B * w


def _shapes():
    return [Shape("omega_s", 0.2, 40.0, n_grid=8), Shape("delta", 0.3, 5.0, n_grid=5), Shape("eps", 0.05, 10.0, n_grid=8)]


def _data(w, seed):
    rng = np.random.default_rng(seed)
    e = rng.normal(scale=0.05, size=len(w))
    e = np.convolve(e, np.ones(5) / np.sqrt(5), mode="same")  # coloured within a block
    block = np.repeat(np.arange(N_BLOCKS), int(np.ceil(len(w) / N_BLOCKS)))[: len(w)]
    return _friction(w) + e, block


@pytest.mark.parametrize("seed", [1, 2])
def test_stribeck_shape_recovered_within_its_sandwich_uncertainty(seed):
    rng = np.random.default_rng(100 + seed)
    n = 6000
    # slow sweeps through both directions over 0..25 rad/s (every speed of the curve is measured)
    t = np.arange(n) / n
    w = 25.0 * np.sin(2 * np.pi * 3 * t) * np.abs(np.sin(2 * np.pi * 0.5 * t + 0.3)) + rng.normal(scale=0.02, size=n)
    y, block = _data(w, seed)
    prof = fit_separable(y, stribeck_design(w), ["T_C", "dT", "b"], block, _shapes(), jackknife=False)
    vp = vp_shape(y, stribeck_design(w), block, _shapes(), prof.shape)
    assert vp.weak == []
    assert vp.cv_rmse <= vp.cv_rmse_start + 1e-12  # the refinement never raises the CV error
    for name, true in (("omega_s", W_S), ("delta", DELTA), ("eps", EPS)):
        se = vp.se[name]
        assert 0 < se < 0.5 * true  # identified: uncertain by less than half its size
        assert abs(vp.shape[name] - true) < 3 * se, (name, vp.shape[name], se)


def test_shape_in_a_speed_gap_is_reported_with_a_wide_uncertainty():
    rng = np.random.default_rng(7)
    n = 6000
    # the same curve, measured only below omega_s / 4 and above 4 omega_s (the curve's knee is never seen)
    t = np.arange(n) / n
    slow = 1.0 * np.sin(2 * np.pi * 20 * t)
    fast = np.sign(np.sin(2 * np.pi * 2 * t)) * (18.0 + 4.0 * np.abs(np.sin(2 * np.pi * 7 * t)))
    w = np.where((np.arange(n) // 250) % 2 == 0, slow, fast) + rng.normal(scale=0.02, size=n)
    y, block = _data(w, 3)
    prof = fit_separable(y, stribeck_design(w), ["T_C", "dT", "b"], block, _shapes(), jackknife=False)
    vp = vp_shape(y, stribeck_design(w), block, _shapes(), prof.shape)
    # the knee is interpolated: omega_s is uncertain by more than half its size (sweep above: well below), and
    # the truth is within the reported uncertainty
    assert vp.se["omega_s"] > 0.5 * vp.shape["omega_s"], (vp.shape, vp.se)
    assert abs(vp.shape["omega_s"] - W_S) < 3 * vp.se["omega_s"]


def test_cv_residuals_are_leave_one_block_out():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(90, 2))
    y = X @ [1.0, -2.0] + rng.normal(size=90)
    block = np.repeat(np.arange(3), 30)
    r = cv_residuals(y, X, block)
    for b in range(3):
        m = block == b
        beta = np.linalg.lstsq(X[~m], y[~m], rcond=None)[0]
        assert np.allclose(r[m], y[m] - X[m] @ beta, atol=1e-8)
