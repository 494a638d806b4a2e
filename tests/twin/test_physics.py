"""The twin's three-body physics: residual equations, closure, friction, parameters."""

import numpy as np
import pytest
import torch

from hd_twin import physics as ph


def _consistent_state(p, effects, n=200, seed=0):
    """A state that satisfies r1..r4 exactly by construction (forces from the closure, Q's from the balances)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    u = 1e-6 * np.sin(7 * t + rng.uniform())
    y = -2e-6 * np.cos(5 * t)
    phi = 1e-3 * np.sin(3 * t)
    om = 50 * np.sin(2 * t)
    d = lambda a: np.gradient(a, t)  # noqa: E731
    F_b, F_mx, F_my, F_FS = ph.closure_forces(np, p, effects, u, d(u), y, d(y), phi, d(phi), om)
    th_m_dd, th_f_dd = rng.normal(0, 100, n), rng.normal(0, 1, n)
    x_dd, y_dd = d(d(u)) + p.r_b * th_m_dd, d(d(y))
    Q_res = F_b * p.r_b + p.J_in * th_m_dd
    Q_red = F_my * p.r_m - p.J_CS * th_f_dd
    # r2 and r3 close with the implied "free" inertial terms: choose masses' accelerations consistent
    return dict(Q_res=Q_res, Q_red=Q_red, theta_m_dd=th_m_dd, theta_f_dd=th_f_dd,
                x_FS_dd=(F_b - F_mx) / p.m_FSx, y_FS_dd=(-F_FS - F_my) / p.m_FSy,
                F_b=F_b, F_mx=F_mx, F_my=F_my, F_FS=F_FS)


def test_residuals_zero_on_consistent_state_numpy_and_torch():
    p = ph.TwinParams.from_yaml()
    eff = list(ph.DEFAULT_EFFECTS)
    s = _consistent_state(p, eff)
    r = ph.residuals(np, p, eff, **s)
    for j, rj in enumerate(r):
        scale = ph.residual_scales(p, 100.0)[j]
        assert np.max(np.abs(rj)) < 1e-9 * scale, f"r{j + 1}"
    rt = ph.residuals(torch, p, eff, **{k: torch.from_numpy(v) for k, v in s.items()})
    for a, b in zip(r, rt):
        np.testing.assert_allclose(b.numpy(), a, rtol=0, atol=1e-9)


def test_residuals_detect_a_wrong_term():
    p = ph.TwinParams.from_yaml()
    eff = list(ph.DEFAULT_EFFECTS)
    s = _consistent_state(p, eff)
    s["Q_red"] = s["Q_red"] + 1.0  # 1 N*m unmodelled output torque shows up in r4 only
    r = ph.residuals(np, p, eff, **s)
    np.testing.assert_allclose(r[3], -1.0, atol=1e-9)
    assert np.max(np.abs(r[0])) < 1e-9
    # an output-side extra term of -1 N*m (F_m r_m = Q_red + Q_out + J_CS theta_f'') absorbs it
    r = ph.residuals(np, p, eff, Q_out=-np.ones_like(s["Q_red"]), **s)
    assert np.max(np.abs(r[3])) < 1e-9


def test_inertia_switch():
    p = ph.TwinParams()
    z = np.zeros(3)
    kw = dict(Q_res=z, Q_red=z, theta_m_dd=np.ones(3), theta_f_dd=np.ones(3), x_FS_dd=np.ones(3), y_FS_dd=np.ones(3),
              F_b=z, F_mx=z, F_my=z, F_FS=z)
    r_with = ph.residuals(np, p, ["inertia", "linear_stiffness"], **kw)
    r_without = ph.residuals(np, p, ["linear_stiffness"], **kw)
    np.testing.assert_allclose(r_with[0], -p.J_in)
    np.testing.assert_allclose(r_with[3], -p.J_CS)
    assert all(np.all(r == 0) for r in r_without)


def test_lossless_static_ratio():
    """Lossless steady state of the closure: F_m r_m = N F_b r_b (T_out = N T_in)."""
    p = ph.TwinParams()
    eff = ["linear_stiffness"]
    F_b_target = 10.0
    u = np.array([-F_b_target / p.k_b])
    # radial balance without flank friction: F_b = mu_g F_m  -> choose y so that F_m = F_b / mu_g at phi
    F_m = F_b_target / p.mu_g
    y = np.array([-F_m / p.k_FS])
    phi = np.array([(p.mu_g * u[0] + y[0] - F_m / p.k_m) / p.r_m])
    z = np.zeros(1)
    F_b, F_mx, F_my, F_FS = ph.closure_forces(np, p, eff, u, z, y, z, phi, z, z)
    assert F_b[0] == pytest.approx(F_b_target)
    assert F_mx[0] == pytest.approx(F_b_target)
    assert F_my[0] * p.r_m == pytest.approx(p.N * F_b[0] * p.r_b)
    assert F_FS[0] == pytest.approx(-F_my[0])
    # the series stiffness: twist per output torque equals 1/K_out
    assert (-phi[0]) / (F_my[0] * p.r_m) == pytest.approx(1.0 / p.K_out, rel=1e-9)


def test_input_friction_effects():
    p = ph.TwinParams()
    w = np.array([-100.0, -1.0, 0.0, 1.0, 100.0])
    assert np.all(ph.input_friction(np, p, [], w) == 0)
    c = ph.input_friction(np, p, ["coulomb_friction"], w)
    np.testing.assert_allclose(c, p.T_C * np.tanh(w / p.eps_omega))
    v = ph.input_friction(np, p, ["viscous_friction"], w)
    np.testing.assert_allclose(v, p.b_visc * w)
    s = ph.input_friction(np, p, ["stribeck_friction"], w)
    assert s[3] > c[3] and s[4] == pytest.approx(c[4], rel=1e-6)  # Stribeck hump only at low speed
    cold = ph.input_friction(np, p, ["viscous_friction", "temperature_dependent_friction", "coulomb_friction"], w,
                             temperature=np.full(5, -10.0))
    warm = ph.input_friction(np, p, ["viscous_friction", "temperature_dependent_friction", "coulomb_friction"], w,
                             temperature=np.full(5, p.T_ref))
    assert abs(cold[4]) > abs(warm[4])
    ld = ph.input_friction(np, p, ["load_dependent_friction"], w, Q_red=np.full(5, 100.0))
    np.testing.assert_allclose(ld, p.c_L * 100 * np.tanh(w / p.eps_omega))
    # torch gives the same numbers
    wt = torch.from_numpy(w)
    eff = ["coulomb_friction", "stribeck_friction", "viscous_friction", "temperature_dependent_friction"]
    np.testing.assert_allclose(
        ph.input_friction(torch, p, eff, wt, torch.full((5,), 0.0)).numpy(),
        ph.input_friction(np, p, eff, w, np.full(5, 0.0)), rtol=1e-7)


def test_params_yaml_meta_and_validation(tmp_path):
    p = ph.TwinParams.from_yaml()
    assert p.mu_g == pytest.approx(p.r_m / (p.N * p.r_b))
    assert 5e5 < p.K_out < 2e6  # size-65 K3 ~ 1.0e6 N*m/rad (size-25 catalogue 5.7e4 scaled)
    q = p.with_meta(gear_ratio=160, torque_constant=0.2)
    assert q.N == 160 and q.k_t == 0.2 and p.N != 160
    with pytest.raises(ValueError, match="k_m"):
        ph.TwinParams(k_m=-1.0).validate()
    with pytest.raises(ValueError, match="N"):
        p.with_meta(gear_ratio=float("nan"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("params: {r_b: fast}\n")
    with pytest.raises(ValueError, match="bad.yaml.*r_b"):
        ph.TwinParams.from_yaml(bad)
    bad.write_text("params: {r_x: 1}\n")
    with pytest.raises(ValueError, match="unknown parameter"):
        ph.TwinParams.from_yaml(bad)
    with pytest.raises(ValueError, match="not found"):
        ph.TwinParams.from_yaml(tmp_path / "none.yaml")
    rt = ph.TwinParams.from_dict(p.to_dict())
    assert rt == p
    with pytest.raises(ValueError):
        ph.check_effects(["inertia", "inertia"])
    with pytest.raises(ValueError):
        ph.closure_forces(np, p, ["inertia"], *([np.zeros(2)] * 7))


def test_quasi_static_baseline_matches_closure():
    p = ph.TwinParams()
    eff = ["linear_stiffness", "mesh_friction", "coulomb_friction"]
    tau = np.array([5.0, -5.0])
    om = np.array([100.0, 100.0])  # driving, then back-driven (torque against motion)
    Q = ph.quasi_static_Q_red(p, eff, tau, om)
    Q_res = tau - p.T_C * np.tanh(om / p.eps_omega)
    F_my = Q / p.r_m
    F_b = Q_res / p.r_b
    F_mx = p.mu_g * F_my + p.mu_c * np.abs(F_my) * np.sign(om)
    np.testing.assert_allclose(F_b, F_mx, rtol=1e-9)
    # driving: the output gets less than N * Q_res; back-driven: the output must supply more
    assert abs(Q[0]) < p.N * abs(Q_res[0]) and abs(Q[1]) > p.N * abs(Q_res[1])
