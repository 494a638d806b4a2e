"""Effect registry isolation, wear to failure, fleets and the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from hd_sim import REGISTRY, EffectSet, nominal, simulate_mission
from hd_sim.plant import derived

#: derived model parameters each effect may change (on top of the baseline); nothing else may move.
OWNED = {
    "stribeck_friction": {"stribeck_on"},
    "temperature_dependent_friction": {"tdf_on"},
    "load_dependent_friction": {"mu_c"},
    "position_periodic_friction": {"F1", "F2", "F3", "F4"},
    "bearing_load_friction": {"mu_bb"},
    "nonlinear_stiffness": {"nl_on", "torsion_law"},
    "hysteresis": {"hyst_on", "z_max", "bw_beta", "bw_gamma", "torsion_law"},
    # law choices (hd_sim.effects.LAW_SLOTS)
    "smooth_friction": {"eps_v", "friction_law"},
    "lugre_friction": {"eps_v", "fric_law", "lg_sigma0", "lg_sigma1", "friction_law"},
    "cubic_stiffness": {"k_m1", "tors_law", "k_cub", "torsion_law"},
    "deadzone_stiffness": {"j_bl", "w_bl", "torsion_law"},
    "kinematic_error_harmonic": {"A1", "A2", "A4", "B1", "B2"},
    "position_dependent_stiffness": {"eps_s"},
    "cogging_torque": {"C1", "C2"},
    "current_ripple": {"r6", "r12"},
    "motor_thermal_drift": {"drift_on"},
    "position_periodic_torque": {"P1", "P2"},
    "backlash": {"j_bl", "w_bl", "backlash_j"},
    "flexspline_stiffness_loss": {"k_FS", "fs_loss", "K_out_lin", "bw_A", "bw_beta", "bw_gamma", "z_max"},
    "lubrication_loss": {"lube_loss", "T_C", "T_C_out", "b_in", "b_out", "mu_c", "mu_bb"},
}


def test_every_non_baseline_effect_is_listed_and_switchable():
    non_base = {n for n, e in REGISTRY.items() if not e.baseline}
    sensor_or_fault = {"dropouts", "torque_sensor_bandwidth", "drive_speed_estimate", "stamp_jitter"}
    assert non_base - sensor_or_fault == set(OWNED)
    base = EffectSet.baseline()
    assert base.is_on("coulomb_friction") and base.is_on("viscous_friction")
    assert not base.is_on("nonlinear_stiffness") and not base.is_on("stribeck_friction")


@pytest.mark.parametrize("name", sorted(OWNED))
def test_effect_changes_only_its_own_terms(name):
    health = {"h_plus": 6e-6, "h_minus": 4e-6}  # some wear, so backlash exists past the preload
    p = nominal()
    base = EffectSet.baseline()
    eff = base.with_on(name)
    if name == "flexspline_stiffness_loss":
        eff = eff.with_params(**{"flexspline_stiffness_loss.loss": 0.2})
    if name == "lubrication_loss":
        eff = eff.with_params(**{"lubrication_loss.severity": 0.5})
    d0 = derived(p, base, health)
    d1 = derived(p, eff, health)
    changed = {k for k in d0 if d0[k] != d1[k]}
    assert changed, f"{name} changed nothing"
    assert changed <= OWNED[name], f"{name} also changed {changed - OWNED[name]}"


def _order_amp(theta, sig, order):
    X = np.column_stack([np.sin(order * theta), np.cos(order * theta), np.ones_like(theta)])
    c, *_ = np.linalg.lstsq(X, sig, rcond=None)
    return float(np.hypot(c[0], c[1]))


def test_single_effects_show_their_signature_in_the_data():
    base = EffectSet.preset("ideal")
    kw = dict(duration=3.0)
    # position-periodic friction, order 2 only
    eff = base.with_on("position_periodic_friction").with_params(**{"position_periodic_friction.order": 2})
    m, tr = simulate_mission(None, eff, "ramp", 1, **kw)
    m0, tr0 = simulate_mission(None, base, "ramp", 1, **kw)
    I, I0 = tr["internal"], tr0["internal"]
    mov = np.abs(I["omega_m"]) > 5.0
    s = np.sign(I["omega_m"][mov])
    ref = lambda J, mv, sg: (J["T_fric_in"][mv] - J["T_fric_in"][mv].mean() * 0) * sg  # noqa: E731
    a2 = _order_amp(I["theta_m"][mov], ref(I, mov, s), 2)
    a1 = _order_amp(I["theta_m"][mov], ref(I, mov, s), 1)
    a2_0 = _order_amp(I0["theta_m"][mov], ref(I0, mov, np.sign(I0["omega_m"][mov])), 2)
    assert a2 == pytest.approx(0.12, rel=0.1) and a1 < 0.01 and a2_0 < 0.01
    # cogging: constant-amplitude order N_c torque, zero without the effect
    m, tr = simulate_mission(None, base.with_on("cogging_torque"), "ramp", 1, **kw)
    Ic = tr["internal"]
    assert _order_amp(Ic["theta_m"], Ic["T_cog"], 60) == pytest.approx(0.20, rel=0.02)
    assert _order_amp(Ic["theta_m"], Ic["T_cog"], 120) == pytest.approx(0.05, rel=0.05)
    assert np.all(tr0["internal"]["T_cog"] == 0)
    # kinematic error order 2 only
    eff = base.with_on("kinematic_error_harmonic").with_params(**{"kinematic_error_harmonic.order": 2,
                                                                   "kinematic_error_harmonic.a_T": 0.0})
    m, tr = simulate_mission(None, eff, "ramp", 1, **kw)
    I = tr["internal"]
    assert _order_amp(I["theta_m"], I["theta_KE"], 2) == pytest.approx(4e-5, rel=0.02)
    assert _order_amp(I["theta_m"], I["theta_KE"], 1) < 0.1 * 4e-5  # leakage of a short window only
    # ... and it is visible in the measured transmission angle (load encoder vs motor encoder)
    # (TE of PHYSICS.md 6.1: remove the elastic part with the nominal stiffness, then order-track)
    K = tr["effects"]["params"]["K_out_lin"]
    te = m.theta_f - m.theta_m / m.meta.gear_ratio + m.Q_red / K
    te0 = m0.theta_f - m0.theta_m / m0.meta.gear_ratio + m0.Q_red / K
    a_ke, a_0 = _order_amp(m.theta_m, te - np.convolve(te, np.ones(101) / 101, "same"), 2), \
        _order_amp(m0.theta_m, te0 - np.convolve(te0, np.ones(101) / 101, "same"), 2)
    assert a_ke > 0.5 * 4e-5 > 3 * a_0


def test_wear_grows_monotonically_to_failure():
    from hd_sim.fleet import simulate_life

    p = nominal()
    p["mission_hours"] = 1.5e4  # compressed life: a few missions of 1 s
    rows = simulate_life(p, 60, None, duration=1.0, seed=3, profiles=("inspection", "flight"))
    h = np.array([r["h"] for r in rows])
    assert np.all(np.diff(h) > 0)
    assert rows[-1]["failed"] and h[-1] >= p["h_fail"] and not any(r["failed"] for r in rows[:-1])
    assert 3 <= len(rows) < 60
    hp = np.array([r["h_plus"] for r in rows])
    hm = np.array([r["h_minus"] for r in rows])
    assert not np.allclose(hp, hm)  # flanks wear differently
    # wear maps to the health parameters: stiffness down, backlash, KE and mesh friction up
    eff = EffectSet.default()
    d_new = derived(p, eff, {"h_plus": 0.0, "h_minus": 0.0})
    d_old = derived(p, eff, {"h_plus": hp[-1], "h_minus": hm[-1]})
    assert d_old["k_m_eff"] < 0.8 * d_new["k_m_eff"]
    assert d_old["backlash_j"] > 0 == d_new["backlash_j"]
    assert d_old["A2"] > 2 * d_new["A2"] and d_old["mu_c"] > d_new["mu_c"]


def test_small_fleet_bags_are_contract_bags(small_fleet_dir):
    from hd_bag import read_mission, validate_bag

    bags = sorted(small_fleet_dir.glob("*/*.mcap"))
    assert len(bags) == 9
    assert [b.name for b in bags[:3]] == sorted(b.name for b in bags[:3])
    hs = []
    for b in bags[:3]:
        assert not validate_bag(b)
        m = read_mission(b, include_sim=True)
        assert m.meta.gear_ratio == 101 and m.n == 3000
        hs.append(float(np.asarray(m.sim["/sim/health"]["h"]).ravel()[0]))
        assert "F_b" in m.sim["/sim/internal"]
    assert hs[0] < hs[1] < hs[2]


def test_cli_mission_effects_and_params(tmp_path, capsys):
    from hdphm.cli import main

    out = tmp_path / "m.mcap"
    rc = main(["sim", "mission", "--out", str(out), "--duration", "0.5", "--preset", "baseline",
               "--effect", "stribeck_friction=on", "--param", "stribeck_friction.ratio=1.5", "--seed", "4"])
    assert rc == 0 and out.exists()
    from hd_bag import read_mission
    import json

    m = read_mission(out, include_sim=True)
    eff = m.sim["/sim/effects"]
    eff = json.loads(eff) if isinstance(eff, str) else eff  # the reader decodes the JSON
    assert eff["effects"]["stribeck_friction"]["on"] and eff["effects"]["stribeck_friction"]["ratio"] == 1.5
    assert not eff["effects"]["cogging_torque"]["on"]
    assert main(["sim", "effects"]) == 0
    assert "position_periodic_friction" in capsys.readouterr().out
    with pytest.raises(KeyError, match="nonsense"):
        main(["sim", "mission", "--out", str(out), "--effect", "nonsense=on", "--duration", "0.2"])
