"""bench/diag_hi_fusion.py: the fused-HI weights and the rise at failure read from operator records.

Known answers: two features whose per-unit gains scatter independently and equally are fused half and half and the
fused rise scatters less than either (by ~1/sqrt 2); a feature with large per-mission noise loses weight when the
noise counts; a feature perfectly correlated with the first adds nothing; the rise of a straight ramp is read at the
failure mission, not where the last missions' average lies (short lives would otherwise read low).
"""

import importlib.util
from pathlib import Path

import numpy as np

from hd_prognostic.pipeline import ActuatorData

_BENCH = Path(__file__).resolve().parents[2] / "bench" / "diag_hi_fusion.py"
_spec = importlib.util.spec_from_file_location("diag_hi_fusion_for_tests", _BENCH)
fus = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fus)


def _gains(n=400, seed=0):
    rng = np.random.default_rng(seed)
    return np.exp(rng.normal(0, 0.1, (n, 2)))  # two features, independent per-unit gains, equal scatter


def test_independent_gains_are_fused_half_and_half_and_scatter_less():
    R = _gains()
    R = R / R.mean(axis=0)
    w = fus.fuse_weights(R)
    assert abs(w[0] - 0.5) < 0.05 and abs(w.sum() - 1) < 1e-9
    sd_single = np.std(np.log(R), axis=0, ddof=1)
    sd_fused = np.std(np.log(R @ w), ddof=1)
    assert sd_fused < 0.8 * sd_single.min()


def test_noisy_feature_loses_weight_and_a_copy_adds_nothing():
    R = _gains(seed=1)
    R = R / R.mean(axis=0)
    rng = np.random.default_rng(2)
    D = np.column_stack([rng.normal(0, 0.01, 2000), rng.normal(0, 0.5, 2000)])  # feature 2 very noisy per mission
    w = fus.fuse_weights(R, D)
    assert w[0] > 0.9
    Rc = np.column_stack([R[:, 0], R[:, 0]])  # a copy: the weight split is arbitrary, the scatter the same
    wc = fus.fuse_weights(Rc)
    assert abs(np.std(np.log(Rc @ wc), ddof=1) - np.std(np.log(R[:, 0]), ddof=1)) < 1e-6


def test_rise_read_at_the_failure_mission():
    mi = np.arange(0, 30)
    y = 1.0 + 0.1 * mi  # a ramp: at the failure mission 30 the level is 4.0, the first mission's 1.0
    a = ActuatorData("U0", [""] * len(mi), mi, mi * 6.0, [{"HI": v} for v in y])
    r, d, e0, Y, m = fus.unit_rises(a, ["HI"], fail_mission=30.0, early=10, last=10)
    assert abs(r[0] - 3.0) < 1e-9 and abs(e0[0] - 1.0) < 1e-9
    # the plain mean of the last 10 would read 1.0 + 0.1 * 24.5 = 3.45 -> rise 2.45: 18 % low
    assert abs(d[:, 0] - 0.1).max() < 1e-12
