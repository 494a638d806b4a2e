"""hd_twin.identify: separable least squares with a CV-identified shape, on synthetic drives with known truth."""

import numpy as np
import pytest

from hd_twin.identify import (Identified, IdentifyError, Shape, derivative, fit_separable, identify_torque_balance,
                              sg_window)

N, ETA, J, T_C, B = 50.0, 0.8, 2e-4, 0.3, 0.004


def drive(seed, *, width=0.5, nfiles=3, T=6.0, fs=1000.0, cross=True, target="tau_m", noise=0.01):
    """Files of a motor-side balance tau_m = J a + Q/(N eta) + T_C tanh(w/width) + b w, noise on ``target`` only."""
    rng = np.random.default_rng(seed)
    files = []
    for _ in range(nfiles):
        t = np.arange(0, T, 1 / fs)
        w = 20 * np.sin(2 * np.pi * 0.3 * t + rng.uniform(0, 6)) + 5 * np.sin(2 * np.pi * 1.1 * t + rng.uniform(0, 6))
        if not cross:
            w = np.abs(w) + 3.0
        a = np.gradient(w, t)
        q = 30 * np.sin(2 * np.pi * 0.17 * t + rng.uniform(0, 6)) + 10 * rng.standard_normal()
        tau = J * a + q / (N * ETA) + T_C * np.tanh(w / width) + B * w
        if target == "tau_m":
            tau = tau + noise * rng.standard_normal(len(t))
        else:
            q = q + noise * N * ETA * rng.standard_normal(len(t))
        files.append({"t": t, "omega_m": w, "tau_m": tau, "Q_red": q})
    return files


def test_recovers_width_and_coefficients_with_calibrated_uncertainty():
    truth = np.array([1 / (N * ETA), J, T_C, B])
    zw, zc = [], []
    for seed in range(6):
        r = identify_torque_balance(drive(seed), "tau_m", const="no")
        assert r.names == ["Q_red", "alpha_m", "coulomb", "omega_m"]
        assert r.identified["width"]
        zw.append((r.shape["width"] - 0.5) / r.shape_sd["width"])
        zc.append((r.coef - truth) / r.sd)
        assert abs(r.shape["width"] - 0.5) < 0.05  # 10 %
    zw, zc = np.array(zw), np.array(zc)
    # every estimate within 4 SD, and the SDs neither wildly optimistic nor pessimistic
    assert np.all(np.abs(zw) < 4), zw
    assert np.all(np.abs(zc) < 4), np.array2string(zc, precision=2)
    assert 0.3 < np.sqrt(np.mean(zw**2)) < 2.5, zw
    assert 0.3 < np.sqrt(np.mean(zc**2)) < 2.5, zc


def test_q_red_target_reads_gear_and_friction():
    r = identify_torque_balance(drive(11, width=2.0, target="Q_red"), "Q_red", const="no")
    a = r.coef[r.names.index("tau_m")]
    assert a == pytest.approx(N * ETA, rel=2e-3)
    assert -r.coef[r.names.index("coulomb")] / a == pytest.approx(T_C, rel=0.05)
    assert r.shape["width"] == pytest.approx(2.0, rel=0.1) and r.identified["width"]


def test_width_without_zero_crossings_is_flagged_not_identified():
    r = identify_torque_balance(drive(3, cross=False), "tau_m")
    assert r.identified["width"] is False
    assert any("no zero crossings" in n for n in r.notes)
    assert "const" not in r.names  # collinear with the Coulomb term: never added


def test_width_below_the_noise_is_a_bound_not_a_value():
    # a hard sign (width far below the speed noise): the data only bound the width
    files = drive(4, width=1e-4)
    rng = np.random.default_rng(0)
    for f in files:
        f["omega_m"] = f["omega_m"] + 0.05 * rng.standard_normal(len(f["t"]))
    r = identify_torque_balance(files, "tau_m", const="no")
    assert r.identified["width"] is False and any("upper bound" in n for n in r.notes)
    assert r.coef[r.names.index("coulomb")] == pytest.approx(T_C, rel=0.1)


def test_constant_only_when_identified():
    files = drive(5)
    r0 = identify_torque_balance(files, "tau_m")
    assert "const" not in r0.names
    for f in files:
        f["tau_m"] = f["tau_m"] + 0.05
    r1 = identify_torque_balance(files, "tau_m")
    assert "const" in r1.names and r1.coef[-1] == pytest.approx(0.05, abs=0.01)


def test_roundtrip_and_predict():
    files = drive(6)
    r = identify_torque_balance(files, "tau_m")
    r2 = Identified.from_dict(r.to_dict())
    p1, p2 = r.predict(files[0]), r2.predict(files[0])
    np.testing.assert_allclose(p1, p2)
    err = files[0]["tau_m"] - p1
    assert np.sqrt(np.mean(err[50:-50] ** 2)) < 0.02  # noise 0.01 plus derivative-filter error
    with pytest.raises(IdentifyError):
        Identified.from_dict({"format": "other"})


def test_single_dict_with_file_index_equals_list():
    files = drive(7, nfiles=2, T=4)
    merged = {k: np.concatenate([f[k] for f in files]) for k in files[0]}
    merged["file"] = np.repeat([0, 1], len(files[0]["t"]))
    a = identify_torque_balance(files, "tau_m", const="no")
    b = identify_torque_balance(merged, "tau_m", const="no")
    np.testing.assert_allclose(a.coef, b.coef)


def test_derivative_designed_at_the_rate():
    assert sg_window(2000.0) > sg_window(200.0)
    for fs in (200.0, 2000.0):
        t = np.arange(0, 4, 1 / fs)
        d = derivative(np.sin(2 * np.pi * 2 * t), t)
        true = 2 * np.pi * 2 * np.cos(2 * np.pi * 2 * t)
        w = sg_window(fs)
        assert np.max(np.abs(d - true)[w:-w]) < 0.02 * 4 * np.pi  # edges: one-sided fits


def test_fit_separable_flags_a_flat_profile():
    rng = np.random.default_rng(1)
    x = rng.standard_normal(4000)
    y = 2 * x + 0.1 * rng.standard_normal(4000)
    block = np.repeat(np.arange(8), 500)
    # the second column does not depend on the shape: its profile is flat, so the shape is not identified
    r = fit_separable(y, lambda sh: np.stack([x, np.ones_like(x)], 1), ["x", "c"], block,
                      [Shape("s", 0.1, 10.0)])
    assert r.identified["s"] is False and r.coef[0] == pytest.approx(2.0, abs=0.01)


def test_bad_input_is_named():
    with pytest.raises(IdentifyError, match="target"):
        identify_torque_balance(drive(0), "Q_x")
    with pytest.raises(IdentifyError, match="'t'"):
        identify_torque_balance([{"omega_m": np.ones(10), "tau_m": np.ones(10)}], "tau_m")


def test_cached_savgol_derivative_equals_scipy_savgol_filter():
    """The cached-weight derivative (used at every streamed sample) is scipy's savgol_filter, edges included."""
    from scipy.signal import savgol_filter

    from hd_twin.identify import _sg_derivative

    rng = np.random.default_rng(3)
    for n, w, p, dt in ((50, 11, 3, 1e-3), (1000, 41, 3, 4e-3), (17, 15, 3, 5e-3), (300, 7, 2, 1e-2)):
        x = rng.normal(size=n).cumsum()
        ref = savgol_filter(x, w, p, deriv=1, delta=dt)
        np.testing.assert_allclose(_sg_derivative(x, w, p, dt), ref, rtol=0, atol=1e-9 * np.abs(ref).max())
