"""Friction (lubrication) monitor: reference law, excess seen and flagged, block == scalar, silent without Q_red."""

import math

import numpy as np
import pytest

from hd_onboard.config import OnboardConfig
from hd_onboard.detectors.friction import FrictionMonitor, fit_friction_reference
from hd_onboard.detectors.levels import ERROR, OK

FS, EPS, SCALE = 1000.0, 0.05, 110.0


def _signals(n, rng, dL=0.0, b=-40.0, a=12.0):
    """Bidirectional sinusoidal motion; residual = a + (b - dL) tanh(omega/eps) + noise [N*m]."""
    t = np.arange(n) / FS
    w = 30.0 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 0.3, n)
    r = a + (b - dL) * np.tanh(w / EPS) + rng.normal(0, 150.0, n)
    return r, w


def test_reference_law_recovered_and_none_without_motion_or_data():
    rng = np.random.default_rng(1)
    r, w = _signals(5000, rng)
    ref = fit_friction_reference(r, w, EPS, SCALE)
    assert ref is not None and abs(ref.b + 40.0) < 10.0 and abs(ref.a - 12.0) < 10.0
    assert fit_friction_reference(r, np.full_like(w, 20.0), EPS, SCALE) is None  # one direction only
    assert fit_friction_reference(np.full_like(r, np.nan), w, EPS, SCALE) is None  # Q_red not measured
    assert fit_friction_reference(r, w, EPS, 0.0) is None


def test_excess_seen_flagged_and_block_equals_scalar():
    rng = np.random.default_rng(2)
    r0, w0 = _signals(5000, rng)
    ref = fit_friction_reference(r0, w0, EPS, SCALE)
    r_h, w_h = _signals(8000, rng)
    r_f, w_f = _signals(8000, rng, dL=3.0 * SCALE)  # friction torque +3 N*T_C
    r, w = np.concatenate([r_h, r_f]), np.concatenate([w_h, w_f])
    r[100:110] = np.nan  # dropouts are skipped, not fatal
    mb = FrictionMonitor(2.0, 2.0, 2.5, 500, 0.05, FS)
    ms = FrictionMonitor(2.0, 2.0, 2.5, 500, 0.05, FS)
    mb.ref = ms.ref = ref
    xb = np.concatenate([mb.step(r[a:a + 700], w[a:a + 700], np.ones(len(r[a:a + 700]), bool))[0]
                         for a in range(0, len(r), 700)])
    xs = np.array([ms.step_one(float(ri), float(wi))[0] for ri, wi in zip(r, w)])
    np.testing.assert_allclose(xb, xs, rtol=1e-9, atol=1e-9, equal_nan=True)
    healthy, faulted = xb[3000:8000], xb[14000:]
    assert np.nanmax(np.abs(healthy)) < 1.0
    assert np.nanmedian(faulted) == pytest.approx(3.0, abs=0.5)
    assert mb.level() == ERROR and ms.level() == ERROR and mb.n_eval == ms.n_eval > 0


def test_silent_without_reference_or_q_red():
    m = FrictionMonitor()
    x, w_, e_ = m.step(np.ones(100), np.ones(100), np.ones(100, bool))
    assert np.isnan(x).all() and not w_.any() and m.level() == OK
    rng = np.random.default_rng(3)
    m.ref = fit_friction_reference(*_signals(3000, rng), EPS, SCALE)
    x, w_, e_ = m.step(np.full(2000, np.nan), _signals(2000, rng)[1], np.ones(2000, bool))
    assert np.isnan(x).all() and not w_.any() and math.isnan(m.step_one(math.nan, 3.0)[0])


@pytest.mark.parametrize("kw", [{"fric_excess_warn": 3.0, "fric_excess_error": 2.0}, {"fric_tau_s": -1.0},
                                {"fric_min_var_u": 1.5}, {"fric_persistence_s": math.nan}])
def test_config_rejects_absurd_friction_parameters(kw):
    with pytest.raises(ValueError, match="fric_"):
        OnboardConfig(**kw).validate()
