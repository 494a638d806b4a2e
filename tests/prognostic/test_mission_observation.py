"""One per-mission observation for the prognostic node and batch: same windows, same reduction, same numbers."""

import math

import numpy as np
import pytest

pytest.importorskip("hd_sim.plant")


def _mission(h_um=20.0, seed=1, duration=6.0, dropout=False, q_nan=False):
    from hd_sim.params import nominal
    from hd_sim.plant import simulate_mission

    m, _ = simulate_mission(nominal(), None, "inspection", seed, duration=duration,
                            health={"h_plus": h_um * 1e-6, "h_minus": h_um * 1e-6}, mission_index=3)
    if q_nan:
        m.Q_red[:] = np.nan
    if dropout:  # NaN samples and a 0.3 s hole in the stream (a dropout the onboard core must survive)
        m.theta_f[500:540] = np.nan
        keep = np.ones(m.n, bool)
        keep[2100:2400] = False
        for k in ("t", "theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red", "segment"):
            setattr(m, k, np.asarray(getattr(m, k))[keep])
    return m


def _node_rows(m):
    """The rows the prognostic node receives: the onboard core with the onboard node's feature function."""
    from hd_onboard.batch import run_mission
    from hd_onboard.core import OnboardCore
    from hd_onboard.features import window_feature_fn

    core = OnboardCore(gear_ratio=m.meta.gear_ratio,
                       feature_fn=window_feature_fn({"torque_constant": m.meta.torque_constant}, m.meta.gear_ratio))
    return run_mission(m, core)["windows"]


@pytest.mark.parametrize("kind", ["clean", "dropout", "no_torque_sensor"])
def test_batch_and_node_give_the_same_observation(kind):
    from hd_onboard.config import OnboardConfig
    from hd_onboard.features import (OBS_WINDOW_S, onboard_window_features, mission_observation,
                                     mission_observation_features)
    from hd_prognostic.tracker import TRACKER_DEFAULTS, ActuatorTracker

    assert OBS_WINDOW_S == OnboardConfig().window_s  # batch uses the onboard node's window length
    m = _mission(dropout=kind == "dropout", q_nan=kind == "no_torque_sensor")
    rows = _node_rows(m)
    batch_w = onboard_window_features(m)
    assert len(rows) == len(batch_w) >= 5
    assert [r["t_start"] for r in rows] == [w["t_start"] for w in batch_w]
    batch = mission_observation_features(m)
    # the node's own reduction (the tracker's), fed the onboard core's rows, without ROS
    tr = ActuatorTracker("EMA-T", None, dict(TRACKER_DEFAULTS))
    tr.add_windows(rows)
    y_node, W_node = tr._mission_obs()
    assert math.isfinite(y_node) and y_node > 0 and W_node > 0
    assert y_node == pytest.approx(batch["HF_MTW_IF"], rel=1e-9, abs=0)
    assert W_node == pytest.approx(batch["W_load"], rel=1e-9, abs=0)
    # and every reduced feature agrees, with the node rows' "feat." keys
    node_all = mission_observation(rows)
    for k in ("ke_2x", "ke_1x", "lost_motion", "te_rms", "ke_indicator", "compliance_residual"):
        np.testing.assert_allclose(node_all[k], batch[k], rtol=1e-9, err_msg=k)
    assert node_all["n_windows"] == batch["n_windows"] == len(rows)


def test_reduction_rules_and_bad_input():
    from hd_onboard.features import mission_observation

    rows = [{"feat.HF_MTW_IF": 1.0, "feat.W_load": 2.0}, {"feat.HF_MTW_IF": float("nan"), "feat.W_load": 3.0},
            {"HF_MTW_IF": 5.0, "W_load": float("nan")}, {"feat.HF_MTW_IF": 3.0}]
    o = mission_observation(rows)
    assert o["HF_MTW_IF"] == 3.0  # median of the finite window values 1, 5, 3
    assert o["W_load"] == 5.0  # exposure: the sum
    assert o["n_windows"] == 4 and o["n_windows_hf"] == 3
    assert math.isnan(mission_observation([])["HF_MTW_IF"]) and math.isnan(mission_observation([])["W_load"])
    with pytest.raises(TypeError, match="window 1"):
        mission_observation([{"HF_MTW_IF": 1.0}, [1.0, 2.0]])


def test_observation_grows_with_wear():
    from hd_onboard.features import mission_observation_features

    y = [mission_observation_features(_mission(h, duration=4.0))["HF_MTW_IF"] for h in (0.0, 20.0, 40.0)]
    assert np.all(np.diff(y) > 0), y


def test_orders_are_averaged_coherently_over_windows():
    """Window phasors of a fixed-phase order plus noise: the coherent mean recovers the amplitude, the
    median of the window amplitudes carries the Rayleigh bias of the noise."""
    from hd_onboard.features import mission_observation

    rng = np.random.default_rng(4)
    A, phi, sig, n = 10e-6, 0.7, 8e-6, 400
    a = A * np.cos(phi) + sig * rng.standard_normal(n)
    b = A * np.sin(phi) + sig * rng.standard_normal(n)
    amp = np.hypot(a, b)
    rows = [{"feat.ke_2x": float(x), "feat.HF_MTW_IF": float(x), "feat.ke_2x_s": float(s), "feat.ke_2x_c": float(c)}
            for x, s, c in zip(amp, a, b)]
    o = mission_observation(rows)
    assert o["HF_MTW_IF"] == o["ke_2x"]
    assert abs(o["ke_2x"] - A) < 0.1 * A
    assert np.median(amp) > 1.3 * A  # what the median of amplitudes would have said
    # rows without phasors (an older onboard): the median of the amplitudes
    o2 = mission_observation([{k: v for k, v in r.items() if not k.endswith(("_s", "_c"))} for r in rows])
    assert o2["HF_MTW_IF"] == pytest.approx(np.median(amp))
