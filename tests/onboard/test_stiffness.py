"""Torsional-stiffness monitor: reference law, block/scalar equality, detection on the plant simulator."""
import math

import numpy as np
import pytest

from tests.onboard.simfix import faulted_mission, sim_mission

from hd_onboard.batch import run_mission  # noqa: E402
from hd_onboard.config import OnboardConfig  # noqa: E402
from hd_onboard.core import OnboardCore  # noqa: E402
from hd_onboard.residuals import RESIDUAL_COLUMNS  # noqa: E402
from hd_onboard.detectors.levels import ERROR, OK  # noqa: E402
from hd_onboard.detectors.stiffness import StiffnessMonitor, StiffnessReference, fit_stiffness_reference, stiffness_basis  # noqa: E402


def _law(Q):
    """Hardening torsion law (rad): compliance 1.2, 1.0, 0.8 urad/(N*m) with knots at 300, 700 N*m."""
    C = np.array([0.8e-6, 0.2e-6, 0.2e-6])
    return -(stiffness_basis(Q, 300.0, 700.0) @ C)


def test_reference_recovers_law_and_refuses_no_load():
    rng = np.random.default_rng(0)
    Q = 1000 * np.sin(np.linspace(0, 20, 4000))
    w = np.cos(np.linspace(0, 20, 4000)) * 50
    tw = 0.3 + _law(Q) + 2e-5 * np.tanh(w) + 1e-6 * rng.standard_normal(len(Q))
    r = fit_stiffness_reference(tw, Q, w, eps=1.0)
    grid = np.linspace(-900, 900, 50)
    # knots are learnt (|Q| quantiles), not the law's: the piecewise-linear fit is within 3 % of the twist range
    assert np.max(np.abs((r.g(grid) + r.a - 0.3) - _law(grid))) < 0.03 * np.max(np.abs(_law(grid)))
    assert abs(r.b - 2e-5) < 2e-6 and r.compliance < 0
    assert fit_stiffness_reference(tw, np.full_like(Q, 5.0), w, eps=1.0) is None  # no load variation
    assert fit_stiffness_reference(tw[:50], Q[:50], w[:50], eps=1.0) is None  # too few samples
    back = StiffnessReference.from_dict(r.to_dict())
    assert back.c == r.c
    with pytest.raises(ValueError, match="q1 < q2"):
        StiffnessReference.from_dict({**r.to_dict(), "q1": 900.0, "q2": 10.0})


def test_monitor_sees_compliance_change_block_equals_scalar():
    rng = np.random.default_rng(1)
    n = 20000
    t = np.arange(n) / 1000.0
    Q = 900 * np.sin(2 * np.pi * 0.7 * t)
    w = 60 * np.cos(2 * np.pi * 0.7 * t)
    scale = np.where(t < 10, 1.0, 1.25)  # 25 % more compliance = 20 % stiffness lost
    tw = 0.1 + scale * _law(Q) + 1e-5 * np.tanh(w) + 2e-6 * rng.standard_normal(n)
    tw[5000:5010] = np.nan
    ref = fit_stiffness_reference(tw[:4000], Q[:4000], w[:4000], eps=1.0)
    a = StiffnessMonitor(tau_s=1.0, loss_warn=0.1, loss_error=0.3, persistence=200)
    b = StiffnessMonitor(tau_s=1.0, loss_warn=0.1, loss_error=0.3, persistence=200)
    a.ref = b.ref = ref
    la, wa, ea = [], [], []
    for i in range(0, n, 777):
        l_, w_, e_ = a.step(tw[i:i + 777], Q[i:i + 777], w[i:i + 777], np.isfinite(tw[i:i + 777]))
        la.append(l_), wa.append(w_), ea.append(e_)
    la, wa = np.concatenate(la), np.concatenate(wa)
    lb = np.array([b.step_one(*v)[0] for v in zip(tw.tolist(), Q.tolist(), w.tolist())])
    np.testing.assert_allclose(lb, la, rtol=1e-9, atol=1e-12, equal_nan=True)
    assert np.nanmax(np.abs(la[(t > 3) & (t < 10)])) < 0.03  # healthy: loss ~ 0
    assert abs(np.nanmedian(la[t > 16]) - 0.2) < 0.02  # 1 - 1/1.25
    first = t[np.flatnonzero(wa)[0]]
    assert 10.0 < first < 14.0 and not wa[t < 10].any()
    assert a.level() != OK and b.level() == a.level()
    assert not ea.__len__() == 0 and a.level() != ERROR  # 20 % < error line 30 %


def test_core_stiffness_on_sim_missions():
    """Healthy: no stiffness flag; 70 % flexspline stiffness loss mid-mission: flagged after onset."""
    h = run_mission(sim_mission(1, 21, duration=16.0))
    core = h["core"]
    st = core.stiffness_status()
    assert st["reference"] == "mission warm-up" and st["n_eval"] > 1000 and st["level"] == OK
    assert h["table"].shape[1] == len(RESIDUAL_COLUMNS) and not any("stiffness" in e[2] for e in h["events"])
    assert all("stiffness.loss" in w for w in h["windows"])
    f = run_mission(faulted_mission(8.0, "flexspline_stiffness_loss", 0.7, actuator=1, seed=21, duration=16.0))
    ev = [e for e in f["events"] if "stiffness" in e[2]]
    assert ev, f["events"]
    t_flag = (ev[0][0] - 1_700_000_000_000_000_000) * 1e-9
    assert 8.0 < t_flag < 16.0
    st = f["core"].stiffness_status()
    assert st["loss"] > 0.15 and st["level"] >= 1
    # the ground's reference (from the healthy mission) gives the same verdict
    c2 = OnboardCore(gear_ratio=f["core"].params.N)
    c2.set_stiffness_reference(core.stiffness.ref.to_dict() | {"source": "ground"})
    m = faulted_mission(8.0, "flexspline_stiffness_loss", 0.7, actuator=1, seed=21, duration=16.0)
    g = run_mission(m, c2)
    assert g["core"].stiffness_status()["reference"] == "ground"
    assert any("stiffness" in e[2] for e in g["events"])


def test_stiffness_config_validation():
    with pytest.raises(ValueError, match="stiff_loss_warn"):
        OnboardConfig(stiff_loss_warn=0.5, stiff_loss_error=0.2).validate()
    with pytest.raises(ValueError, match="stiff_tau_s"):
        OnboardConfig(stiff_tau_s=math.nan).validate()
    with pytest.raises(ValueError, match="sigma_floor_rel"):
        OnboardConfig(sigma_floor_rel=2.0).validate()
