"""Inputs, features, pre-processing, differentiation and the actuator-level split."""

import numpy as np
import pytest

from hd_twin import data as D
from tests.twin.synth import synth_fleet, synth_mission


def test_split_never_leaks_actuators_or_missions():
    rng = np.random.default_rng(1)
    for trial in range(50):
        n_act = int(rng.integers(2, 12))
        keys = [(f"A{a}", f"A{a}/m{i}") for a in range(n_act) for i in range(int(rng.integers(1, 5)))]
        tr, va = D.split_missions(keys, 0.25, seed=trial)
        assert sorted(tr + va) == list(range(len(keys)))
        assert not ({keys[i][0] for i in tr} & {keys[i][0] for i in va})  # no actuator on both sides
        assert tr and va
        if n_act >= 4:
            assert len({keys[i][0] for i in va}) == round(0.25 * n_act)
    # single actuator: split by whole missions
    keys = [("A0", f"m{i}") for i in range(8)]
    tr, va = D.split_missions(keys, 0.25, 0)
    assert len(va) == 2 and not ({keys[i][1] for i in tr} & {keys[i][1] for i in va})
    assert D.split_missions(keys, 0.25, 0) == (tr, va)  # deterministic
    with pytest.raises(ValueError):
        D.split_missions(keys[:1])


def test_training_windows_never_cross_the_split(tmp_path):
    from hd_twin.train import TrainConfig, train_twin

    ms = synth_fleet(4, 2, duration=2.0)
    res = train_twin(ms, None, TrainConfig.from_preset("tiny", epochs=1, plots=False, export_onnx=False), progress=False)
    tr = {d["actuator_id"] for d in res.config["data"]["train"]}
    va = {d["actuator_id"] for d in res.config["data"]["validation"]}
    assert tr and va and not (tr & va)
    tr_segs, va_segs = res.segments
    assert {s.actuator_id for s in tr_segs} == tr and {s.actuator_id for s in va_segs} == va


def test_features_twist_precision_and_shapes():
    m = synth_mission(duration=1.0)
    X = D.mission_inputs(m)
    assert X.shape == (m.n, 7)
    # a large unwrapped motor angle: the twist is still exact in float64
    X2 = X.copy()
    X2[:, 0] += 2 * np.pi * 1e5 * m.meta.gear_ratio
    X2[:, 3] += 2 * np.pi * 1e5
    F1, F2 = D.features(X, m.meta.gear_ratio, 1 / m.fs), D.features(X2, m.meta.gear_ratio, 1 / m.fs)
    np.testing.assert_allclose(F2[:, 0], F1[:, 0], atol=1e-8)
    assert F1.shape == (m.n, len(D.FEATURES))
    with pytest.raises(ValueError, match="shape"):
        D.features(X[:, :5], 100.0, 1e-3)
    # streaming in two blocks gives the same features as one block
    Fa = D.features(X[:10], m.meta.gear_ratio, 1 / m.fs)
    Fb = D.features(X[10:], m.meta.gear_ratio, 1 / m.fs, prev=X[9])
    np.testing.assert_allclose(np.vstack([Fa, Fb]), F1)
    np.testing.assert_allclose(F1[1:, 11], np.diff(X[:, 1]) * m.fs)


def test_preprocess_nan_gaps_and_decimation():
    m = synth_mission(fs=1000.0, duration=3.0)
    m.Q_red[500:520] = np.nan
    m.tau_m[900] = np.nan
    m.segment = np.where(np.arange(m.n) < 1500, 0, 1).astype(np.int32)
    segs = D.preprocess(m, fs_model=250.0)
    assert len(segs) == 2 and all(abs(s.dt - 0.004) < 1e-12 for s in segs)
    s0 = segs[0]
    assert s0.n == 375 and np.isfinite(s0.X).all() and np.isfinite(s0.theta_m_dd).all()
    assert not s0.mask[500 // 4: 520 // 4].any() and not s0.mask[900 // 4] and s0.mask[50:100].all()
    assert np.isnan(s0.Q_red[~s0.mask & ~s0.edge]).all()  # out of the mask: not measured, or an edge sample
    assert not (s0.mask & s0.edge).any() and s0.edge[0] and s0.edge[-1]
    with pytest.raises(ValueError, match="integer factor"):
        D.preprocess(m, fs_model=300.0)
    m.Q_red[:] = np.nan
    with pytest.raises(ValueError, match="no sample"):
        D.preprocess(m, fs_model=None)


def test_missing_temperature_and_command_map_to_training_mean():
    m = synth_mission(duration=1.0)
    m.temperatures = {}
    m.t_cmd = np.zeros(0)
    m.theta_ref = np.zeros(0)
    s = D.preprocess(m)[0]
    assert np.isnan(s.F[:, 10]).all() and np.isnan(s.F[:, 9]).all()
    assert (s.temperature == 25.0).all()
    norm = D.Normalizer.fit(D.preprocess(synth_mission(duration=1.0)))
    Z = norm.norm_features(s.F)
    assert (Z[:, 9] == 0).all() and (Z[:, 10] == 0).all() and np.isfinite(Z).all()


def test_derivative_scheme_accuracy():
    dt = 1e-3
    t = np.arange(0, 2, dt)
    x = np.sin(2 * np.pi * 3 * t)
    d = D.derivative(x, dt)
    true = 2 * np.pi * 3 * np.cos(2 * np.pi * 3 * t)
    assert np.max(np.abs(d[50:-50] - true[50:-50])) < 1e-3 * np.max(np.abs(true))


def test_find_bags_errors(tmp_path):
    with pytest.raises(ValueError, match="no such"):
        D.find_bags([tmp_path / "nope"])
    with pytest.raises(ValueError, match="no .mcap"):
        D.find_bags([tmp_path])


def test_torsion_law_features_and_older_feature_sets():
    """phi|phi| and phi^3 make a hardening law linear in the features; a stored 13-feature list still works."""
    m = synth_mission(duration=1.0)
    X = D.mission_inputs(m)
    N = m.meta.gear_ratio
    F = D.features(X, N, 1 / m.fs)
    phi = X[:, 3] - X[:, 0] / N
    j2, j3 = D.FEATURES.index("phi_abs_phi"), D.FEATURES.index("phi_cubed")
    np.testing.assert_allclose(F[:, j2], phi * np.abs(phi), rtol=1e-12, atol=0)
    np.testing.assert_allclose(F[:, j3], phi**3, rtol=1e-12, atol=0)
    # a piecewise K1/K2/K3 torque (PHYSICS.md 2.1) is fitted far better with the powers than by phi alone
    a = np.abs(phi).max()
    K1, K2, K3, p1, p2 = 1.0, 1.6, 1.9, 0.2 * a, 0.5 * a
    ap = np.abs(phi)
    T = np.sign(phi) * np.where(ap < p1, K1 * ap, np.where(ap < p2, K1 * p1 + K2 * (ap - p1),
                                                            K1 * p1 + K2 * (p2 - p1) + K3 * (ap - p2)))
    def fit_res(A):
        A = A / np.abs(A).max(axis=0)
        return np.linalg.lstsq(A, T, rcond=None)[1][0]
    assert fit_res(F[:, [0, j2, j3]]) < 0.05 * fit_res(F[:, [0]])
    # friction shapes: regularised sign of omega_m and the load-dependent meshing loss
    js, jt = D.FEATURES.index("sgn_omega_m"), D.FEATURES.index("abs_tau_sgn_omega_m")
    np.testing.assert_allclose(F[:, js], np.tanh(X[:, 1] / D.OMEGA_EPS), rtol=1e-12)
    np.testing.assert_allclose(F[:, jt], np.abs(X[:, 2]) * F[:, js], rtol=1e-12)
    # selection by name: the pre-existing 13-feature models keep their columns
    F13 = D.features(X, N, 1 / m.fs, names=D.FEATURES_V1)
    np.testing.assert_array_equal(F13, F[:, :13])
    s13 = D.preprocess(m, names=D.FEATURES_V1)[0]
    assert s13.F.shape[1] == 13
    with pytest.raises(ValueError, match="unknown twin feature"):
        D.features(X, N, 1 / m.fs, names=("phi", "backlash_angle"))
    # tiny but informative power features are standardised, not left at std 1
    norm = D.Normalizer.fit(D.preprocess(m))
    assert norm.f_std[j3] < 1e-3 and norm.f_std[j3] > 0
