"""PINN loss components: data term, residual scaling, ramp, learnable lambda_c."""

import math

import numpy as np
import pytest
import torch

from hd_twin import data as D
from hd_twin import physics as ph
from hd_twin.model import PINN, LambdaC, LossConfig, ResidualScaler, TwinLSTM, ramp_factor

torch.set_num_threads(1)


def _batch(B=3, T=40, seed=0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.randn(*s, generator=g)  # noqa: E731
    b = {k: r(B, T) for k in ("theta_m_dd", "theta_f_dd", "omega_m", "tau_m", "theta_m", "theta_f", "omega_f")}
    b["phi"] = 1e-4 * r(B, T)
    b["phi_d"] = 1e-3 * r(B, T)
    b["temperature"] = torch.full((B, T), 25.0)
    b["x"] = r(B, T, len(D.FEATURES))
    b["Q_red"] = 10 * r(B, T)
    b["mask"] = torch.ones(B, T, dtype=torch.bool)
    b["dt"] = torch.full((B, 1), 1e-3)
    return b


def _pinn(**kw):
    torch.manual_seed(0)
    cfg = LossConfig(**{"washout": 0, **kw})
    return PINN(TwinLSTM(len(D.FEATURES), 3, 8, 1, 0.0), ph.TwinParams(), list(ph.DEFAULT_EFFECTS), 0.0, 10.0, cfg)


def test_data_loss_is_masked_mse_in_sigma_units():
    m = _pinn()
    b = _batch()
    b["Q_red"][0, 5:9] = float("nan")
    b["mask"][0, 5:9] = False
    res = m.losses(b, physics=False)
    q = res["pred"]["Q_red"].detach()
    ok = b["mask"]
    expect = (((q - torch.nan_to_num(b["Q_red"])) / 10.0)[ok] ** 2).mean()
    assert float(res["L_d"]) == pytest.approx(float(expect), rel=1e-6)
    assert math.isfinite(float(res["L_d"]))
    # washout excludes the first samples of each window
    m2 = _pinn(washout=10)
    res2 = m2.losses(b, physics=False)
    expect2 = (((q - torch.nan_to_num(b["Q_red"])) / 10.0)[:, 10:][ok[:, 10:]] ** 2).mean()
    assert float(res2["L_d"]) == pytest.approx(float(expect2), rel=1e-6)


def test_physics_loss_is_mean_of_scaled_squared_residuals():
    m = _pinn(adaptive_scaling=False)
    m.train()
    b = _batch()
    res = m.losses(b)
    from hd_twin.model import physics_residuals_torch

    r = physics_residuals_torch(m.to_SI(m.net(b["x"])[0]), b, m.params, m.effects)
    s = ph.residual_scales(m.params, 10.0)
    expect = np.mean([float((rj.detach() ** 2).mean()) / s[j] ** 2 for j, rj in enumerate(r)])
    assert float(res["L_c"]) == pytest.approx(expect, rel=1e-4)
    assert float(res["L_c_ref"]) == pytest.approx(expect, rel=1e-4)
    # the total is exp(-s_d) L_d + s_d + ramp * (exp(-s_c) L_c + nu s_c); lambda_c = exp(s_d - s_c)
    s_d, s_c = float(m.lam.s_d), float(m.lam.s)
    tot = math.exp(-s_d) * float(res["L_d"]) + s_d + res["ramp"] * (math.exp(-s_c) * float(res["L_c"]) + 0.08 * s_c)
    assert float(res["L_tot"]) == pytest.approx(tot, rel=1e-5)
    assert m.lam.value().item() == pytest.approx(math.exp(s_d - s_c), rel=1e-6)


def test_adaptive_scaling_switch():
    fixed = np.array([1.0, 2.0, 3.0, 4.0])
    on = ResidualScaler(fixed, adaptive=True, momentum=0.5)
    off = ResidualScaler(fixed, adaptive=False, momentum=0.5)
    for sc in (on, off):
        sc.update(torch.tensor([10.0, 10.0, 10.0, 10.0]))
        sc.update(torch.tensor([20.0, 20.0, 20.0, 20.0]))
    np.testing.assert_allclose(on.scales().numpy(), 15.0)  # 10 then EMA(0.5) with 20
    np.testing.assert_allclose(off.scales().numpy(), fixed)
    # in the loss: with scaling each residual contributes ~1 after the first update
    m = _pinn(adaptive_scaling=True)
    m.train()
    res = m.losses(_batch())
    assert float(res["L_c"]) == pytest.approx(1.0, rel=1e-4)
    # the scales follow the residuals during the ramp, then stay frozen
    m_r = _pinn(adaptive_scaling=True, ramp_epochs=2)
    m_r.train()
    m_r.losses(_batch(seed=1), epoch=0)
    during = m_r.scaler.scales().clone()
    m_r.losses(_batch(seed=2), epoch=1.5)
    assert not torch.equal(during, m_r.scaler.scales())
    frozen = m_r.scaler.scales().clone()
    m_r.losses(_batch(seed=3), epoch=2)
    assert torch.equal(frozen, m_r.scaler.scales())
    m_off = _pinn(adaptive_scaling=False)
    m_off.train()
    assert float(m_off.losses(_batch())["L_c"]) != pytest.approx(1.0, rel=1e-2)


def test_ramp_switch():
    assert ramp_factor(0, 0) == 1.0 and ramp_factor(100, 0) == 1.0
    vals = [ramp_factor(e, 4) for e in range(7)]
    assert vals[0] > 0 and all(a < b for a, b in zip(vals[:4], vals[1:5])) and vals[4] == vals[6] == 1.0
    m = _pinn(ramp_epochs=4)
    m.train()
    b = _batch()
    r0 = m.losses(b, epoch=0)
    r9 = m.losses(b, epoch=9)
    assert r0["ramp"] < 1.0 and r9["ramp"] == 1.0
    assert float(r0["L_tot"] - m.lam.total(r0["L_d"], None)) < float(r9["L_tot"] - m.lam.total(r9["L_d"], None))


def test_lambda_c_cannot_collapse_to_zero():
    """A raw learnable weight on a positive loss runs away; the uncertainty form settles at nu L_d / L_c > 0."""
    L_d, L_c = torch.tensor(0.02), torch.tensor(5.0)
    raw = torch.nn.Parameter(torch.tensor(0.08))
    lam = LambdaC(0.08, "uncertainty")
    opt = torch.optim.Adam([raw, *lam.parameters()], lr=0.1)
    traj = []
    for _ in range(1200):
        opt.zero_grad()
        (L_d + raw * L_c + lam.total(L_d, L_c)).backward()
        opt.step()
        traj.append(lam.value().item())
    assert raw.item() < 0  # the naive form runs away (through zero)
    expect = 0.08 * 0.02 / 5.0
    assert min(traj) > 0.5 * expect and lam.value().item() == pytest.approx(expect, rel=0.05)
    # better-satisfied physics (smaller L_c) -> larger weight
    lam2 = LambdaC(0.08, "uncertainty")
    opt2 = torch.optim.Adam(lam2.parameters(), lr=0.1)
    for _ in range(1200):
        opt2.zero_grad()
        lam2.total(L_d, torch.tensor(0.2)).backward()
        opt2.step()
    assert lam2.value().item() == pytest.approx(0.08 * 0.02 / 0.2, rel=0.05)
    # bounded even for a vanishing physics loss
    lam3 = LambdaC(0.08, "uncertainty", lam_max=10.0)
    with torch.no_grad():
        lam3.s.fill_(-50.0)
    assert lam3.value().item() == pytest.approx(10.0)


def test_lambda_fixed_zero_is_pure_data():
    m = _pinn(lambda_mode="fixed", lambda_init=0.0)
    m.train()
    res = m.losses(_batch())
    assert float(res["L_tot"]) == float(res["L_d"])
    assert list(m.lam.parameters()) == []
    with pytest.raises(ValueError):
        LambdaC(0.0, "uncertainty")
    with pytest.raises(ValueError):
        LambdaC(0.1, "raw")


def test_physics_gradient_reaches_the_network():
    m = _pinn()
    m.train()
    res = m.losses(_batch())
    g = torch.autograd.grad(res["L_c"], list(m.net.parameters()), allow_unused=True)
    assert any(x is not None and float(x.abs().sum()) > 0 for x in g)


def test_parameter_calibration_is_learnable_and_regularised():
    torch.manual_seed(0)
    cfg = LossConfig(washout=0)
    m = PINN(TwinLSTM(len(D.FEATURES), 3, 8, 1, 0.0), ph.TwinParams(), list(ph.DEFAULT_EFFECTS), 0.0, 10.0, cfg,
             calibrate=["k_m", "T_C"], calib_reg=0.5)
    m.train()
    res = m.losses(_batch())
    g = torch.autograd.grad(res["L_tot"], [m.calib])[0]
    assert torch.all(g != 0)  # the physics term reaches the parameters
    with torch.no_grad():
        m.calib.copy_(torch.tensor([0.1, -0.2]))
    cp = m.calibrated_params()
    assert cp.k_m == pytest.approx(ph.TwinParams().k_m * math.exp(0.1), rel=1e-6)
    assert cp.T_C == pytest.approx(ph.TwinParams().T_C * math.exp(-0.2), rel=1e-6)
    assert cp.k_b == ph.TwinParams().k_b  # not calibrated: the prior
    r = m.losses(_batch())
    base = m.lam.total(r["L_d"], r["L_c"], r["ramp"])
    assert float(r["L_tot"] - base) == pytest.approx(0.5 * (0.1**2 + 0.2**2), rel=1e-4)  # the prior term
    with pytest.raises(ValueError, match="cannot calibrate"):
        PINN(TwinLSTM(len(D.FEATURES), 3, 8, 1, 0.0), ph.TwinParams(), list(ph.DEFAULT_EFFECTS), 0.0, 10.0, cfg,
             calibrate=["N"])
