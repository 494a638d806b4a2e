"""The speed re-timing discovery identifies is carried into the twin (hd_twin.speedtiming, issue 10).

Discovery re-times a logged speed (omega + tau omega') when the drive's speed estimate lags its angle and the
re-timed speed lowers the fit bags' CV error; the twin version it writes must carry tau, and the twin must
evaluate the found terms on the same speeds (batch: centred derivative, as discovery; streaming: causal).
A config without the entry leaves everything bit-for-bit as before.
"""

import dataclasses
import json

import numpy as np
import pytest

from hd_twin import data as D
from hd_twin import physics as ph
from hd_twin.speedtiming import CausalRetimer, SpeedTiming, retime_speed, sg2_derivative
from hd_twin.terms import evaluate_terms

FS = 1000.0


def _X(n=4000, f=2.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    X = np.zeros((n, 7))
    X[:, 1] = 3 * np.sin(2 * np.pi * f * t) + 0.5 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 1e-3, n)
    X[:, 4] = X[:, 1] / 50
    return t, X


def test_absent_entry_is_the_logged_speed_bit_for_bit():
    t, X = _X()
    for entry in (None, {}):
        st = SpeedTiming.from_config(entry)
        assert not st.active and st.apply_X(X, t) is X and st.to_config() == {}


@pytest.mark.parametrize("entry, msg", [({"omega_x": {"tau_s": 1e-3}}, "unknown speed"),
                                        ({"omega_m": {"tau_s": 0.05}}, "half the derivative window"),
                                        ({"omega_m": 3e-3}, "tau_s"), ({"omega_m": {"tau_s": "x"}}, "numbers")])
def test_bad_entry_is_refused_naming_the_problem(entry, msg):
    with pytest.raises(ValueError, match=msg):
        SpeedTiming.from_config(entry, "model/config.json speed_timing")


def test_streaming_retiming_is_causal_blockwise_and_close_to_batch():
    t, X = _X()
    st = SpeedTiming.from_config({"omega_m": {"tau_s": 4e-3, "se": 1e-4}})
    batch = st.apply_X(X, t)
    assert np.array_equal(batch[:, 4], X[:, 4]) and np.array_equal(batch[:, [0, 2, 3, 5, 6]], X[:, [0, 2, 3, 5, 6]])
    r = CausalRetimer(st, FS)
    whole = r.step(X)
    r.reset()
    blocks = np.vstack([r.step(X[i:i + 37]) for i in range(0, len(X), 37)])
    assert np.allclose(blocks, whole, rtol=0, atol=1e-12)  # state carried across calls
    r.reset()
    cut = r.step(X[:2000])[1000:2000, 1]
    assert np.allclose(cut, whole[1000:2000, 1], rtol=0, atol=1e-12)  # no look-ahead: later rows change nothing
    c_b, c_s = (batch[:, 1] - X[:, 1])[50:], (whole[:, 1] - X[:, 1])[50:]
    assert np.sqrt(np.mean((c_s - c_b) ** 2)) < 0.05 * np.sqrt(np.mean(c_b ** 2))


def _lagged(m, f_c=50.0):
    """The drive's speed estimate: backward difference of the logged angle, first-order low-pass at f_c."""
    x = np.r_[m.omega_m[0], np.diff(m.theta_m) * FS]
    a = np.exp(-2 * np.pi * f_c / FS)
    from scipy.signal import lfilter

    w, _ = lfilter([1 - a], [1, -a], x, zi=[a * x[0]])
    return dataclasses.replace(m, omega_m=w, omega_f=w / float(m.meta.gear_ratio))


@pytest.fixture(scope="module")
def discovered(tmp_path_factory):
    from hd_ground.discovery.pipeline import run_discovery
    from tests.ground.conftest import synth_mission

    eff = {"position_periodic_friction": (0.04, 2, 0.7)}
    ms = [_lagged(synth_mission(s, effects=eff, index=s, T=8.0)) for s in (0, 1)]
    out = tmp_path_factory.mktemp("disc")
    rep = run_discovery(["bag0", "bag1"], out, missions=ms, log=lambda s: None, plots=False, within_bag_check=False)
    return ms, rep, json.loads((out / "twin" / "config.json").read_text())


def _twin_tau_rmse(cfg, m, timing_entry):
    """RMSE of the twin's motor-torque model from a discovery-written config on mission ``m``: the twin's
    physics (hd_twin.physics.q_res with the config's params, declared effects and extra terms) plus the
    recorded load path J_eq alpha_m + inv_eta Q_red / N, on the speeds the twin's re-timing gives."""
    seg = np.zeros(m.n, int)
    sig = SpeedTiming.from_config(timing_entry).apply({"omega_m": m.omega_m, "theta_m": m.theta_m}, m.t, seg)
    w = sig["omega_m"]
    alpha = sg2_derivative(w, m.t, seg, 0.02)
    N = float(m.meta.gear_ratio)
    p = dataclasses.replace(ph.TwinParams.from_yaml(), **{k: float(v) for k, v in cfg["params"].items()}).with_meta(N)
    terms = [t for t in cfg["extra_terms"] if t["signal"] == "tau_m"]
    s = {"theta_m": m.theta_m, "omega_m": w, "alpha_m": alpha, "Q_red": m.Q_red, "tau_m": m.tau_m}
    effects = ph.equation_effects(cfg["declared_effects"], cfg["extra_terms"])  # as the twin's PINN evaluates them
    Q_res = ph.q_res(np, p, effects, m.tau_m, w, None, m.Q_red, evaluate_terms(terms, s))
    base = cfg["discovery"]["baseline_refit"]["tau_m"]
    err = Q_res - base["J_eq"] * alpha - base["inv_eta"] * m.Q_red / N  # = tau_m - the twin's tau_m
    rows = slice(int(0.2 * m.n), None)  # discovery scores the held-out bag after its calibration part
    return float(np.sqrt(np.mean(err[rows] ** 2)))


def test_discovery_writes_the_retiming_and_the_twin_reproduces_its_heldout_error(discovered):
    ms, rep, cfg = discovered
    assert "omega_m" in rep["speed_lags"], rep["data_notes"]
    tau = rep["speed_lags"]["omega_m"]
    a = np.exp(-2 * np.pi * 50.0 / FS)
    assert tau == pytest.approx((a / (1 - a) + 0.5) / FS, rel=0.1)  # the filter's low-frequency delay
    ent = cfg["speed_timing"]
    assert ent["omega_m"]["tau_s"] == tau and 0 < ent["omega_m"]["se"] < 0.1 * tau
    assert rep["effects"] and rep["effects"][0]["name"] == "position_periodic_friction"
    after = rep["error_after"]["rmse"]
    twin = _twin_tau_rmse(cfg, ms[1], ent)  # bag1 is discovery's held-out bag
    print(f"held-out tau_m RMSE: discovery {after:.5g}, twin from the config {twin:.5g} N*m")
    assert twin == pytest.approx(after, rel=0.05), (twin, after)
    logged = _twin_tau_rmse(cfg, ms[1], None)  # the same config evaluated on the logged speeds
    print(f"the same config on the logged speeds: {logged:.5g} N*m")
    assert logged > 1.2 * after, (logged, after)


def test_twin_preprocessing_applies_the_config_entry_and_nothing_without_it(discovered):
    ms, _, cfg = discovered
    m = ms[1]
    plain = D.preprocess(m, None)
    again = D.preprocess(m, None, speed_timing={})
    assert all(np.array_equal(a.X, b.X) and np.array_equal(a.F, b.F, equal_nan=True) for a, b in zip(plain, again))
    ret = D.preprocess(m, None, speed_timing=cfg["speed_timing"])
    for name, j in (("omega_m", 1), ("omega_f", 4)):
        assert name in cfg["speed_timing"]  # both logged speeds lag their angles here
        want = retime_speed(getattr(m, name), m.t, np.zeros(m.n, int), cfg["speed_timing"][name]["tau_s"])
        assert np.allclose(ret[0].X[:, j], want, rtol=0, atol=1e-12)
    assert np.array_equal(ret[0].X[:, [0, 2, 3]], plain[0].X[:, [0, 2, 3]])


def test_trained_twin_stores_the_entry_and_streams_on_the_retimed_speeds(tmp_path):
    """Training with an entry writes it to config.json; the ONNX runtime applies it causally at the input rate
    (its output equals the same network fed speeds re-timed by CausalRetimer); without the entry the runtime
    is the one of every earlier model."""
    from hd_twin.runtime import StreamingTwin
    from tests.twin.synth import synth_mission, tiny_twin_with_and_without

    entry = {"omega_m": {"tau_s": 3e-3, "se": 1e-4}, "window_s": 0.02}
    d_new, d_old = tiny_twin_with_and_without(tmp_path, "speed_timing", entry)
    m = synth_mission("EMA-NEW", 9, seed=123, duration=1.0)
    X = D.mission_inputs(m)
    new, old = StreamingTwin(d_new, fs_in=m.fs), StreamingTwin(d_old, fs_in=m.fs)
    q_new = np.concatenate([new.step(X[i:i + 64])["Q_red"] for i in range(0, len(X), 64)])
    q_ref = old.step(CausalRetimer(SpeedTiming.from_config(entry), m.fs).step(X))["Q_red"]
    assert np.allclose(q_new, q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))
    old.reset(m.fs)
    assert not np.allclose(old.step(X)["Q_red"], q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))


def test_model_config_for_training_takes_the_entry(tmp_path):
    """`hdphm train --model-config OUT/twin/config.json` (discovery's version) trains on the re-timed speeds."""
    from hd_twin.cli import _model_config

    entry = {"omega_m": {"tau_s": 3e-3, "se": 1e-4}, "window_s": 0.02}
    p = tmp_path / "config.json"
    p.write_text(json.dumps({"declared_effects": ["inertia"], "extra_terms": [], "speed_timing": entry}))
    assert _model_config(str(p))["speed_timing"] == entry
    p.write_text(json.dumps({"declared_effects": ["inertia"], "speed_timing": {"omega_m": {"tau_s": 1.0}}}))
    with pytest.raises(SystemExit, match="half the derivative window"):
        _model_config(str(p))
    p.write_text(json.dumps({"declared_effects": ["inertia"]}))
    assert "speed_timing" not in _model_config(str(p))
