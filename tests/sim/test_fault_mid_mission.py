"""Faults that start inside a mission (simulate_mission(fault=...), hdphm sim mission --fault)."""

from __future__ import annotations

import numpy as np
import pytest

from hd_sim import EffectSet, simulate_mission
from hd_sim.plant import parse_fault

SIG = ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")
T_ON = 1.0


def _pair(fault, preset="default", seed=4, duration=2.0, **kw):
    eff = EffectSet.preset(preset)
    a = simulate_mission(None, eff, "inspection", seed, duration=duration, **kw)
    b = simulate_mission(None, eff, "inspection", seed, duration=duration, fault=fault, **kw)
    return a, b


@pytest.mark.parametrize("fault", [{"name": "lubrication_loss", "severity": 3.0, "t_onset": T_ON},
                                   {"name": "flexspline_stiffness_loss", "severity": 0.4, "t_onset": T_ON}])
def test_before_onset_bit_identical_after_onset_different(fault):
    (ma, ta), (mb, tb) = _pair(fault)
    pre = ma.t < T_ON
    assert np.array_equal(ma.t, mb.t) and pre.sum() == 1000
    for nm in SIG:
        x, y = getattr(ma, nm), getattr(mb, nm)
        assert np.array_equal(x[pre], y[pre], equal_nan=True), nm
    for nm, x in ta["internal"].items():
        assert np.array_equal(x[pre], tb["internal"][nm][pre], equal_nan=True), nm
    post = ma.t >= T_ON + 0.2
    assert np.abs(mb.Q_red[post] - ma.Q_red[post]).max() > 1.0  # N*m: the fault is seen at the output
    fa = tb["internal"]["fault_active"]
    assert fa[pre].max() == 0.0 and fa[~pre].min() == 1.0
    assert "fault_active" in ta["internal"] and ta["internal"]["fault_active"].max() == 0.0
    rec = tb["effects"]["fault"]
    assert rec["name"] == fault["name"] and rec["t_onset"] == pytest.approx(T_ON) and "fault" not in ta["effects"]


def test_lubrication_loss_multiplies_friction_as_the_effect_law():
    """Baseline (no temperature-dependent friction): T_fric = m(t) (T_C tanh(w/eps) + b w) exactly."""
    sev, ramp = 2.5, 0.1
    (_, ta), (_, tb) = _pair({"name": "lubrication_loss", "severity": sev, "t_onset": T_ON, "t_ramp": ramp},
                             preset="ideal")
    I, P = tb["internal"], tb["effects"]["params"]
    phi = I["fault_phi"]
    t = I["t"]
    # the ramp: linear from the onset over t_ramp, then held
    assert phi[t < T_ON].max() == 0.0 and phi[t >= T_ON + ramp].min() == 1.0
    mid = (t > T_ON + 0.01) & (t < T_ON + ramp - 0.01)
    np.testing.assert_allclose(phi[mid], (t[mid] - T_ON) / ramp + 1 / (ramp / P["dt"]), rtol=0, atol=1e-9)
    mult = 1.0 + sev * phi
    eps_f = P["eps_v"] / P["N"]
    T_out = mult * (P["T_C_out"] * np.tanh(I["omega_f"] / eps_f) + P["b_out"] * I["omega_f"])
    T_in = mult * (P["T_C"] * np.tanh(I["omega_m"] / P["eps_v"]) + P["b_in"] * I["omega_m"])
    np.testing.assert_allclose(I["T_fric_out"], T_out, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(I["T_fric_in"], T_in, rtol=1e-12, atol=1e-12)
    after = t >= T_ON + ramp
    moving = after & (np.abs(I["omega_f"]) > 0.05)
    assert moving.sum() > 50
    ratio = I["T_fric_out"][moving] / ta["internal"]["T_fric_out"][moving]
    assert np.median(ratio) == pytest.approx(1 + sev, rel=0.05)  # same sign of motion, ~same speed


def test_flexspline_stiffness_loss_lowers_k_FS():
    loss = 0.35
    (_, ta), (_, tb) = _pair({"name": "flexspline_stiffness_loss", "severity": loss, "t_onset": T_ON, "t_ramp": 0.0},
                             preset="ideal")
    I, P = tb["internal"], tb["effects"]["params"]
    k_FS = P["k_FS"] * (1.0 - loss * I["fault_phi"])
    np.testing.assert_allclose(I["F_FS"], k_FS * I["y_FS"] + P["c_FS"] * I["y_FS_d"], rtol=1e-12,
                               atol=1e-9 * np.abs(I["F_FS"]).max())
    assert I["fault_phi"][I["t"] >= T_ON].min() == 1.0  # t_ramp 0: a step
    # the flexspline carries the same force, so it deflects 1/(1 - loss) more once loaded
    post = (I["t"] > T_ON + 0.3) & (np.abs(I["F_FS"]) > 0.3 * np.abs(I["F_FS"]).max())
    r = I["y_FS"][post] / ta["internal"]["y_FS"][post]
    assert np.median(r) == pytest.approx(1.0 / (1.0 - loss), rel=0.05)


@pytest.mark.parametrize("fault", [{"name": "lubrication_loss", "severity": 4.0, "t_onset": 0.7},
                                   {"name": "flexspline_stiffness_loss", "severity": 0.5, "t_onset": 0.7,
                                    "t_ramp": 0.02}])
def test_three_body_residuals_vanish_with_a_fault(fault):
    _, tr = simulate_mission(None, EffectSet.default(), "inspection", 5, duration=1.5, fault=fault)
    I, P = tr["internal"], tr["effects"]["params"]
    r = (I["Q_res"] - I["F_b"] * P["r_b"] - P["J_WG"] * I["alpha_m"],
         I["F_b"] - I["F_mx"] - P["m_FSx"] * I["x_FS_dd"],
         -I["F_FS"] - I["F_my"] - P["m_FSy"] * I["y_FS_dd"],
         I["F_my"] * P["r_m"] - I["Q_red"] - P["J_CS"] * I["alpha_f"])
    for ri, sc in zip(r, ("Q_res", "F_b", "F_my", "Q_red")):
        assert np.max(np.abs(ri)) <= 1e-9 * np.abs(I[sc]).max() + 1e-12, sc
    # mesh friction follows the lubrication law too: F_mx - mu_g F_my = mu_c m(t) |F_my| tanh(.)
    if fault["name"] == "lubrication_loss":
        m = 1.0 + fault["severity"] * I["fault_phi"]
        want = P["mu_c"] * m * np.abs(I["F_my"]) * np.tanh(I["omega_m"] / P["eps_v"])
        np.testing.assert_allclose(I["F_mx"] - P["mu_g"] * I["F_my"], want, rtol=1e-9,
                                   atol=1e-9 * np.abs(I["F_mx"]).max())


@pytest.mark.parametrize("name, sev, key, names", [
    ("lubrication_loss", 2.0, "lube_loss", ("T_C", "T_C_out", "b_in", "b_out", "mu_c", "mu_bb")),
    ("flexspline_stiffness_loss", 0.3, "fs_loss", ("k_FS", "bw_A", "bw_beta", "bw_gamma")),
])
def test_after_the_ramp_the_plant_equals_a_mission_started_with_the_fault(name, sev, key, names):
    eff = EffectSet.default()
    _, ta = simulate_mission(None, eff, "inspection", 2, duration=0.6, fault={"name": name, "severity": sev,
                                                                            "t_onset": 0.3})
    _, tb = simulate_mission(None, eff.with_on(name), "inspection", 2, duration=0.6, health={key: sev})
    rec, pa, pb = ta["effects"]["fault"], ta["effects"]["params"], tb["effects"]["params"]
    assert pb[key] == sev and rec["after"] == sev
    fac = {"T_C": "friction_factor", "T_C_out": "friction_factor", "b_in": "friction_factor",
           "b_out": "friction_factor", "mu_c": "friction_factor", "mu_bb": "friction_factor",
           "k_FS": "k_FS_factor", "bw_A": "bw_A_factor", "bw_beta": "bw_beta_factor", "bw_gamma": "bw_beta_factor"}
    for nm in names:
        assert pa[nm] > 0, nm
        assert pa[nm] * rec[fac[nm]] == pytest.approx(pb[nm], rel=1e-9), nm
    if name == "flexspline_stiffness_loss":
        assert rec["z_max_after"] == pytest.approx(pb["z_max"], rel=1e-9) and rec["bw_A_factor"] < 1.0


def test_fault_on_top_of_existing_degradation_never_heals():
    h = {"lube_loss": 1.0}
    eff = EffectSet.default().with_on("lubrication_loss")
    _, tr = simulate_mission(None, eff, "inspection", 1, duration=1.0, health=h,
                             fault={"name": "lubrication_loss", "severity": 3.0, "t_onset": 0.5})
    rec = tr["effects"]["fault"]
    assert rec["before"] == 1.0 and rec["after"] == 3.0 and rec["friction_factor"] == pytest.approx(2.0)
    _, tr = simulate_mission(None, eff, "inspection", 1, duration=1.0, health=h,
                             fault={"name": "lubrication_loss", "severity": 0.5, "t_onset": 0.5})
    assert tr["effects"]["fault"]["friction_factor"] == 1.0


@pytest.mark.parametrize("fault, msg", [
    ({"name": "backlash", "severity": 1.0, "t_onset": 0.5}, "mid-mission faults are"),
    ({"name": "lubrication_loss", "severity": 11.0, "t_onset": 0.5}, "severity"),
    ({"name": "flexspline_stiffness_loss", "severity": float("nan"), "t_onset": 0.5}, "severity"),
    ({"name": "lubrication_loss", "severity": 1.0, "t_onset": 5.0}, "t_onset"),
    ({"name": "lubrication_loss", "severity": 1.0, "t_onset": 0.5, "t_ramp": -1}, "t_ramp"),
    ({"name": "lubrication_loss", "severity": "a lot", "t_onset": 0.5}, "must be numbers"),
    ({"name": "lubrication_loss", "severity": 1.0}, "must be numbers"),
    ({"name": "lubrication_loss", "severity": 1.0, "t_onset": 0.5, "when": 3}, "unknown keys"),
    ("lubrication_loss:3@0.5", "must be a dict"),
])
def test_bad_fault_refused_with_a_clear_error(fault, msg):
    with pytest.raises(ValueError, match=msg):
        simulate_mission(None, None, "inspection", 0, duration=1.0, fault=fault)


def test_parse_fault_and_cli_writes_the_truth(tmp_path):
    assert parse_fault("lubrication_loss:3@10") == {"name": "lubrication_loss", "severity": 3.0, "t_onset": 10.0}
    assert parse_fault("flexspline_stiffness_loss:0.3@8/0.1")["t_ramp"] == 0.1
    with pytest.raises(ValueError, match="NAME:SEVERITY@T_ONSET"):
        parse_fault("lubrication_loss=3")
    from hd_bag import read_mission
    from hdphm.cli import main

    out = tmp_path / "f.mcap"
    assert main(["sim", "mission", "--out", str(out), "--duration", "1.0", "--seed", "2",
                 "--fault", "lubrication_loss:2@0.6/0.01", "--plot", str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    m = read_mission(out, include_sim=True)
    eff = m.sim["/sim/effects"]
    assert eff["fault"]["name"] == "lubrication_loss" and eff["fault"]["t_onset"] == pytest.approx(0.6)
    fa = np.asarray(m.sim["/sim/internal"]["fault_active"])
    t = np.asarray(m.sim["/sim/internal"]["t"])
    assert fa[t < 0.6 - 1e-9].max() == 0.0 and fa[t >= 0.6].min() == 1.0
    with pytest.raises(SystemExit, match="--fault"):
        main(["sim", "mission", "--out", str(tmp_path / "g.mcap"), "--duration", "1.0", "--fault", "grease"])
    with pytest.raises(SystemExit, match="--fault.*not one of"):
        main(["sim", "mission", "--out", str(tmp_path / "g.mcap"), "--duration", "1.0", "--fault", "grease:1@0.5"])
    with pytest.raises(SystemExit, match="severity 1.2 outside"):
        main(["sim", "mission", "--out", str(tmp_path / "g.mcap"), "--duration", "1.0",
              "--fault", "flexspline_stiffness_loss:1.2@0.5"])
    assert not (tmp_path / "g.mcap").exists()


def test_fleet_fault_starts_inside_the_mission_before_its_first_growth():
    from hd_sim import nominal
    from hd_sim.fleet import simulate_life

    eff = EffectSet.default().with_on("lubrication_loss").with_params(
        **{"lubrication_loss.onset": 2.0, "lubrication_loss.rate": 0.5})
    rows = simulate_life(nominal(), 4, None, effects=eff, duration=1.0, seed=1)
    assert [r["lube_loss"] for r in rows] == [0.0, 0.0, 0.5, 0.9]  # growth capped at 0.9
    assert "fault" not in rows[0] and "fault" not in rows[2] and "fault" not in rows[3]
    f = rows[1]["fault"]
    assert f["name"] == "lubrication_loss" and f["before"] == 0.0 and f["after"] == 0.5
    assert 0.2 <= f["t_onset"] <= 0.8 and f["friction_factor"] == pytest.approx(1.5)
