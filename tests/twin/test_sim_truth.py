"""The twin's equations hold on the simulator's true internal states (/sim/internal).

Evaluation-only use of the plant: the test simulates a short mission, takes
the plant's true forces, accelerations and parameters, and checks that the
twin's r1..r4 (hd_twin.physics, the one place of the equations) vanish on
them and that the closure reproduces the plant's bearing and radial forces.
"""

import numpy as np
import pytest

from hd_twin import physics as ph

hd_sim = pytest.importorskip("hd_sim.plant")


@pytest.fixture(scope="module")
def truth(sim_mission):
    """The shared tests/conftest.py fixture: 3 s, realistic default effects (Mission, ground truth)."""
    return sim_mission


def _twin_params(sim_params):
    keep = ("N", "r_m", "r_b", "J_WG", "J_CS", "m_FSx", "m_FSy", "k_b", "c_b", "k_FS", "c_FS", "mu_c")
    d = {k: float(sim_params[k]) for k in keep}
    d["J_rotor"] = 0.0  # the plant's J_WG already includes the rotor
    d["k_m"] = float(sim_params["k_m1"])
    d["c_m"] = float(sim_params["c_m"])
    d["eps_omega"] = float(sim_params["eps_v"])
    return ph.TwinParams.from_dict(d, "plant parameters")


def test_residuals_vanish_on_true_states(truth):
    _, gt = truth
    s = gt["internal"]
    p = _twin_params(gt["effects"]["params"])
    eff = ["inertia", "linear_stiffness"]
    r = ph.residuals(np, p, eff, Q_res=s["Q_res"], Q_red=s["Q_red"], theta_m_dd=s["alpha_m"], theta_f_dd=s["alpha_f"],
                     x_FS_dd=s["x_FS_dd"], y_FS_dd=s["y_FS_dd"], F_b=s["F_b"], F_mx=s["F_mx"], F_my=s["F_my"],
                     F_FS=s["F_FS"])
    scale = ph.residual_scales(p, float(np.std(s["Q_red"])))
    for j, rj in enumerate(r):
        rel = np.sqrt(np.mean(rj**2)) / scale[j]
        assert rel < 1e-6, f"r{j + 1}: RMS {np.sqrt(np.mean(rj**2)):.3g} vs scale {scale[j]:.3g}"
    # and they do not vanish when a term is wrong (the check can fail)
    r_bad = ph.residuals(np, p, eff, Q_res=s["Q_res"], Q_red=1.05 * s["Q_red"], theta_m_dd=s["alpha_m"],
                         theta_f_dd=s["alpha_f"], x_FS_dd=s["x_FS_dd"], y_FS_dd=s["y_FS_dd"], F_b=s["F_b"],
                         F_mx=s["F_mx"], F_my=s["F_my"], F_FS=s["F_FS"])
    assert np.sqrt(np.mean(r_bad[3] ** 2)) > 1e-3 * scale[3]


def test_closure_reproduces_bearing_and_radial_forces(truth):
    _, gt = truth
    s = gt["internal"]
    p = _twin_params(gt["effects"]["params"])
    u = s["x_FS"] - p.r_b * s["theta_m"]
    u_d = s["x_FS_d"] - p.r_b * s["omega_m"]
    phi = s["theta_f"] - s["theta_m"] / p.N
    F_b, _, _, _ = ph.closure_forces(np, p, ["linear_stiffness", "structural_damping", "mesh_friction"], u, u_d,
                                        s["y_FS"], s["y_FS_d"], phi, s["omega_f"] - s["omega_m"] / p.N, s["omega_m"])
    np.testing.assert_allclose(F_b, s["F_b"], rtol=0, atol=1e-6 * np.max(np.abs(s["F_b"])))
    # the radial mesh force from the (nonlinear) true F_my through the twin's wedge + flank-friction law
    F_mx_twin = ph.mesh_radial_force(np, p, ["mesh_friction"], s["F_my"], s["omega_m"])
    np.testing.assert_allclose(F_mx_twin, s["F_mx"], rtol=0, atol=1e-6 * np.max(np.abs(s["F_mx"])))


def test_train_on_simulated_bags_and_stream_a_real_bag(small_fleet_dir, tmp_path):
    """End to end on contract bags: read with hd_bag (no /sim), train tiny, evaluate, stream one bag."""
    from hd_bag import read_mission

    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import TrainConfig, eval_model, load_missions, train_twin

    ms = load_missions([small_fleet_dir], progress=False)
    assert all(not m.sim for m in ms)  # the twin never reads ground truth
    res = train_twin(ms, tmp_path / "m", TrainConfig.from_preset("tiny", epochs=1, fs_target=250.0, plots=False),
                     progress=False)
    assert np.isfinite(res.metrics["validation"]["nrmse_pct"])
    bag = sorted(small_fleet_dir.rglob("*.mcap"))[0]
    met = eval_model(tmp_path / "m", [read_mission(bag)])
    assert np.isfinite(met["r2"])
    out = StreamingTwin(tmp_path / "m").run_mission(read_mission(bag))
    assert len(out["Q_red"]) > 0 and np.isfinite(out["Q_red"]).all()
