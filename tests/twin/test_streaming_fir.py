"""The streaming twin's derivative as fixed FIR weights, and its fixed-lag mode.

* the FIR filters alone (numpy only): the fixed-lag centred filter equals the batch derivative
  (``hd_twin.identify.derivative``, the re-timing's ``sg2_derivative``) however a segment is cut into
  calls, for segments shorter than, equal to and longer than the window; the causal one equals the pre-FIR
  rule (the batch derivative re-run on the history at every call, newest samples kept);
* a trained twin with an identified physics path and speed re-timing, fed at twice its model rate
  (decimation, anti-alias filter): ``mode="causal"`` gives the outputs of the pre-FIR runtime
  (``legacy_physics=True``) to float rounding, sample by sample and in random blocks; ``mode="fixed_lag"``
  gives the batch twin's outputs (physics path, LSTM remainder, x_FS / y_FS, edge flags) to float tolerance,
  ``lag_samples`` late.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.signal import savgol_filter

from hd_twin import data as D
from hd_twin.identify import derivative, sg_window
from hd_twin.speedtiming import SpeedTiming, sg2_derivative
from hd_twin.streamfir import CausalSGHistory, CentredFIR, sg_weights

identify = pytest.importorskip("hd_twin.identify", reason="needs the shared identification (hd_twin.identify)")


def _cuts(n, rng, hi=12):
    c = np.cumsum(rng.integers(1, hi, n))
    return c[c < n]


def _signal(n, dt, rng):
    t = np.arange(n) * dt
    return np.sin(2 * np.pi * 3.1 * t) * 40 + 5 * t + rng.normal(0, 0.05, n)


@pytest.mark.parametrize("n", [2, 5, 31, 32, 33, 400])
def test_fixed_lag_fir_equals_the_batch_derivative_for_any_cuts(n):
    fs, rng = 1000.0, np.random.default_rng(n)
    dt = 1.0 / fs
    w = sg_window(fs)
    assert w == 31  # the window these lengths straddle (n < 3, < w, = w, w + 1, long)
    x = _signal(n, dt, rng)
    ref = derivative(x, np.arange(n) * dt)
    for cuts in (_cuts(n, rng), np.arange(1, n), []):
        f = CentredFIR(sg_weights(w, 3, dt))
        got, lens = [], []
        for part in np.split(x, cuts):
            got.append(f.push(part))
            lens.append(len(got[-1]))
        got.append(f.flush())
        d = np.concatenate(got)
        np.testing.assert_allclose(d, ref, rtol=0, atol=1e-9 * np.nanmax(np.abs(ref)) if n > 2 else 0)
        if n > w + 1 and len(cuts) == n - 1:  # one sample per call: each output m samples late
            assert sum(lens[:w]) == 0 and lens[w] == w // 2 + 2 and set(lens[w + 1:]) == {1}


def test_fixed_lag_fir_handles_several_signals_at_once():
    rng = np.random.default_rng(1)
    dt = 1 / 400.0
    X = np.column_stack([_signal(120, dt, rng), _signal(120, dt, rng) * 3])
    f = CentredFIR(sg_weights(9, 3, dt))
    d = np.concatenate([f.push(p) for p in np.split(X, _cuts(120, rng))] + [f.flush()])
    for j in range(2):
        ref = savgol_filter(X[:, j], 9, 3, deriv=1, delta=dt)  # the batch filter (mode "interp")
        np.testing.assert_allclose(d[:, j], ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_causal_fir_equals_the_pre_fir_rule():
    """Pre-FIR: identify.derivative on (history of at most 2 w + 2 rows + new rows), new rows kept."""
    fs, rng = 250.0, np.random.default_rng(2)
    dt = 1 / fs
    w = sg_window(fs)
    x = _signal(300, dt, rng)
    for cuts in (_cuts(300, rng, 9), np.arange(1, 300)):
        f, hist, got, ref = CausalSGHistory(sg_weights(w, 3, dt)), np.zeros(0), [], []
        for part in np.split(x, cuts):
            got.append(f.step(part))
            H = np.concatenate([hist, part])
            r = derivative(H, np.arange(len(H)) * dt) if len(H) >= 3 else np.zeros(len(H))
            ref.append(r[-len(part):])
            hist = H[-(2 * w + 2):]
        np.testing.assert_allclose(np.concatenate(got), np.concatenate(ref), rtol=0, atol=1e-9 * 2000)


@pytest.mark.parametrize("fs", [100.0, 1000.0])
def test_fixed_lag_retiming_equals_the_batch_retiming(fs):
    rng = np.random.default_rng(3)
    n = 500
    timing = SpeedTiming.from_lags({"omega_m": 3e-3, "omega_f": -1e-3})
    X = rng.normal(0, 1, (n, 7))
    X[:, 1] = _signal(n, 1 / fs, rng)
    X[:, 4] = X[:, 1] / 50
    t = np.arange(n) / fs
    ref = timing.apply_X(X, t)
    r = timing.streamer(fs, fixed_lag=True)
    out = np.vstack([r.step(p) for p in np.split(X, _cuts(n, rng))] + [r.flush()])
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert r.lag == (int(round(0.02 * fs)) | 1) // 2
    d = sg2_derivative(X[:, 1], t, np.zeros(n), 0.02)
    assert np.abs(out[:, 1] - X[:, 1]).max() > 0.5 * 3e-3 * np.abs(d).max()  # the re-timing is not a no-op


# ---- a trained twin ------------------------------------------------------------------------------
ENTRY = {"omega_m": {"tau_s": 3e-3, "se": 1e-4}, "window_s": 0.02}


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    from hd_twin.train import TrainConfig, train_twin
    from tests.twin.synth import synth_fleet

    out = tmp_path_factory.mktemp("twin_fir")
    train_twin(synth_fleet(3, 2, duration=2.0), out, TrainConfig.from_preset(
        "tiny", epochs=1, plots=False, fs_target=None, physics_path="identified", speed_timing=ENTRY), progress=False)
    return out


@pytest.fixture(scope="module")
def mission():
    from tests.twin.synth import synth_mission

    return synth_mission("EMA-FIR", 0, fs=400.0, seed=42, duration=1.5)  # twice the model's 200 Hz


def test_causal_mode_equals_the_pre_fir_runtime(model, mission):
    from hd_twin.runtime import StreamingTwin

    X = D.mission_inputs(mission)
    X[100:104, 1] = np.nan  # a held speed sample
    new = StreamingTwin(model, fs_in=mission.fs)
    old = StreamingTwin(model, fs_in=mission.fs, legacy_physics=True)
    assert new.physpath.active and "alpha_m" in new.physpath.identified.names and new._retimer is not None
    assert new.lag_samples == 0 and new.decimation == 2
    rng = np.random.default_rng(4)
    for cuts in (np.arange(1, 180), _cuts(len(X), rng, 30)):
        new.reset(mission.fs)
        old.reset(mission.fs)
        n = cuts[-1] if len(cuts) < 200 else len(X)
        a = [new.step(p) for p in np.split(X[:n], cuts[cuts < n])]
        b = [old.step(p) for p in np.split(X[:n], cuts[cuts < n])]
        for k in ("Q_red", "Q_phys", "x_FS", "index", "edge"):
            A, B = (np.concatenate([o[k] for o in oo]) for oo in (a, b))
            assert len(A) == len(B) > 0
            np.testing.assert_allclose(A.astype(float), B.astype(float), rtol=0, atol=1e-9 * max(1.0, np.abs(B).max()))
    assert new.flush()["Q_red"].size == 0  # causal: nothing held back


def test_fixed_lag_mode_equals_the_batch_twin(model, mission):
    from hd_twin.modeldir import predict_outputs, q_from_outputs
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import load_pinn

    pinn, norm, cfg = load_pinn(model)
    assert cfg["speed_timing"] == ENTRY
    (seg,) = D.preprocess(mission, cfg["preprocessing"]["fs_model"], names=cfg["features"], speed_timing=ENTRY,
                          T_ref=pinn.params.T_ref)
    outs = predict_outputs(pinn, [seg], norm)
    ref = q_from_outputs(pinn, [seg], outs)[0]
    rem = float(pinn.gate) * (pinn.r_mean + pinn.r_std * outs[0][:, 0])
    X = D.mission_inputs(mission)
    tw = StreamingTwin(model, fs_in=mission.fs, mode="fixed_lag")
    w_phys = sg_window(200.0, float(cfg["physics_path"]["identified"]["cutoff_hz"]))
    # latency: half the physics window at 200 Hz (x2 input rows) + half the 20 ms re-timing window at 400 Hz
    assert tw.lag_samples == 2 * (w_phys // 2) + (int(round(0.02 * 400)) | 1) // 2
    assert tw.edge_s == pytest.approx((w_phys // 2) / 200.0)
    scale = np.abs(ref).max()
    rng = np.random.default_rng(5)
    for cuts in (np.arange(1, len(X)), _cuts(len(X), rng, 40)):
        tw.reset(mission.fs)
        parts = [tw.step(p) for p in np.split(X, cuts)] + [tw.flush()]
        got = {k: np.concatenate([o[k] for o in parts]) for k in ("Q_red", "Q_phys", "x_FS", "y_FS", "sample", "edge")}
        assert np.array_equal(got["sample"], 2 * np.arange(seg.n))  # every model sample, in order, once
        np.testing.assert_allclose(got["Q_phys"], ref - rem, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(got["Q_red"], ref, rtol=0, atol=1e-5 * scale)
        np.testing.assert_allclose(got["Q_red"] - got["Q_phys"], rem, rtol=0, atol=1e-5 * scale)
        np.testing.assert_allclose(got["y_FS"], pinn.y_scale * outs[0][:, 2], rtol=0,
                                   atol=1e-5 * np.abs(pinn.y_scale * outs[0][:, 2]).max())
        assert np.array_equal(got["edge"], D.edge_samples(seg.n, seg.dt))
        # the outputs of a call belong to rows lag_samples back (index < 0: an earlier call's rows)
        if len(cuts) == len(X) - 1:
            late = [i - (o["sample"][-1]) for i, o in enumerate(parts[:-1]) if len(o["sample"])]
            assert max(late) <= tw.lag_samples + 1 and np.median(late) >= tw.lag_samples
    # the causal mode differs from batch where the one-sided derivative extrapolates: the point of fixed-lag
    c = StreamingTwin(model, fs_in=mission.fs)
    qc = np.concatenate([c.step(X[i:i + 20])["Q_phys"] for i in range(0, len(X), 20)])
    assert np.abs(qc - ref + rem)[seg.mask].max() > 1e-3 * scale


def test_run_mission_flushes_each_segment_in_fixed_lag_mode(model, mission):
    from hd_twin.runtime import StreamingTwin

    fl = StreamingTwin(model, mode="fixed_lag").run_mission(mission)
    assert np.array_equal(fl["index"], np.arange(0, mission.n, 2))
    with pytest.raises(ValueError, match="mode must be one of"):
        StreamingTwin(model, mode="centred")


# ---- the onboard core on the fixed-lag twin ------------------------------------------------------
def _core(model, m, fixed_lag):
    from hd_onboard.config import OnboardConfig
    from hd_onboard.core import OnboardCore
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
    cfg = OnboardConfig(twin_fixed_lag=fixed_lag, nominal_fs=m.fs)  # rate known: no restart once it is measured
    return OnboardCore(make_expected(str(model), p, fs_hz=m.fs), p, config=cfg)


def test_onboard_core_pairs_each_measurement_with_its_fixed_lag_twin_output(model, mission):
    """Residual k = measurement k - the (batch-equal) twin output k, whatever the block size; the flag decision
    of sample k is made lag_samples later; every sample gets its row, in stamp order."""
    from hd_onboard.batch import run_mission
    from hd_onboard.core import OnboardCore  # noqa: F401
    from hd_twin.runtime import StreamingTwin

    m = copy.deepcopy(mission)
    m.t_cmd, m.theta_ref = np.zeros(0), np.zeros(0)  # no commands: the twin input does not depend on block starts
    m.tau_m[300:303] = np.nan  # invalid samples (held for the twin, not evaluated)
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    tables = {}
    for block in (1000, 7, 1):
        core = _core(model, m, True)
        assert core.residuals.delayed and core.residuals.lag_samples > 0
        tables[block] = run_mission(m, core, block=block)["table"]
        assert np.array_equal(np.round(tables[block][:, 0] * 1e9).astype(np.int64), stamps)  # every row, in order
    # the per-sample short path (push_one: each sample's row waits, the row lag back is processed)
    core = _core(model, m, True)
    (tt, vv), = m.temperatures.values()
    core.push_temperature(int(m.t0_ns + tt[0] * 1e9), float(vv[0]))
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    block_calls, push = [], core.push
    core.push = lambda *a: block_calls.append(1) or push(*a)
    for s, v in zip(stamps.tolist(), V.tolist()):
        core.push_one(s, v)
    core.end_mission()
    assert len(block_calls) < 0.05 * m.n  # the first samples only (rate, twist check): then the scalar short path
    tables["one"] = core.take_rows()
    for block in (7, 1, "one"):
        assert len(tables[block]) == m.n
        np.testing.assert_allclose(tables[block], tables[1000], rtol=1e-9, atol=1e-9, equal_nan=True)
    tab = tables[1000]
    # the twin's own fixed-lag output on the core's inputs (temperature held, no command), held between model samples
    X = D.mission_inputs(m)
    X[:, 5] = 25.0
    X[:, 6] = np.nan
    X[300:303, 2] = X[299, 2]  # the core holds the last finite input
    tw = StreamingTwin(model, fs_in=m.fs, mode="fixed_lag")
    q = np.concatenate([tw.step(X)["Q_red"], tw.flush()["Q_red"]])
    np.testing.assert_allclose(tab[:, 2], np.repeat(q, 2)[:m.n], rtol=0, atol=1e-9 * np.abs(q).max())
    ev = np.isfinite(tab[:, 3])
    assert ev.sum() > 0.8 * m.n
    np.testing.assert_allclose(tab[ev, 3], (m.Q_red - tab[:, 2])[ev], rtol=1e-12, atol=1e-9)  # residual k: Q_red k - Q_hat k
    assert not ev[-tw.lag_samples:].any()  # the mission's last samples (the batch edge) are not evaluated
    # the causal setting keeps the former twin
    causal = run_mission(m, _core(model, m, False), block=1000)["table"]
    c = StreamingTwin(model, fs_in=m.fs)
    qc = np.concatenate([c.step(X[i:i + 1000])["Q_red"] for i in range(0, m.n, 1000)])
    np.testing.assert_allclose(causal[:, 2], np.repeat(qc, 2)[:m.n], rtol=0, atol=1e-9 * np.abs(qc).max())


def test_onboard_fixed_lag_twin_across_a_dropout(model, mission):
    """A dropout resets the twin: the segment's last rows come out (not evaluated, as the batch edge samples),
    every accepted sample gets its row, and the short path equals the block path."""
    m = mission
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    keep = np.r_[0:350, 380:m.n]  # 30 samples missing (> max_gap_samples): a new segment
    s, V = stamps[keep], V[keep]
    a = _core(model, m, True)
    A = [a.push(s[i:i + 64], V[i:i + 64]).table for i in range(0, len(s), 64)]
    A.append(a.drain().table)
    A = np.concatenate(A)
    b = _core(model, m, True)
    for s_, v_ in zip(s.tolist(), V.tolist()):
        b.push_one(s_, v_)
    b.end_mission()
    B = b.take_rows()
    assert len(A) == len(B) == len(s) and np.array_equal(A[:, 0], s * 1e-9)
    np.testing.assert_allclose(B, A, rtol=1e-9, atol=1e-9, equal_nan=True)
    lag = a.residuals.lag_samples
    assert a.health.n_resets >= 1
    assert not np.isfinite(A[350 - lag + 1:350, 3]).any() and np.isfinite(A[330:350 - lag, 3]).all()  # last rows: not evaluated
