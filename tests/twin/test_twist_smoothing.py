"""theta_f's smoothing for the twist (hd_twin.twistsmooth): the twin reads the twist discovery fitted on.

Discovery may read the twist through a smoothed output angle (core.choose_twist_window); the twin version it
writes carries that smoothing (config.json:twist_smoothing) and the twin's batch pre-processing and its streaming
runtime apply it. Checks: absent entry = the logged angle bit for bit; bad entries refused naming the problem; the
entry discovery writes, applied by the twin's pre-processing, gives discovery's own smoothed twist sample for
sample (per segment); the fixed-lag streamer equals the batch rows whatever the calls, the causal one smooths a
quantised angle about as well; a trained twin stores the entry and streams on the smoothed angle. A few seconds
(the training test trains a tiny network for one epoch)."""

import dataclasses
import json

import numpy as np
import pytest

from hd_twin import data as D
from hd_twin.twistsmooth import (CausalSmoother, CentredSmoother, TwistSmoothing, smooth_angle,
                                 window_samples)

STEP_16 = 2 * np.pi / 2**16


def _quantised(m, step=STEP_16, gap_at=None):
    """Mission ``m`` with theta_f logged in whole counts of ``step``; ``gap_at``: a second segment from there."""
    seg = np.zeros(m.n, int)
    if gap_at is not None:
        seg[gap_at:] = 1
    return dataclasses.replace(m, theta_f=np.round(m.theta_f / step) * step, segment=seg)


@pytest.fixture(scope="module")
def missions():
    from tests.twin.synth import synth_mission

    return [_quantised(synth_mission("EMA-T1", i, fs=1000.0, duration=3.0, seed=i), gap_at=1700 if i == 0 else None)
            for i in range(2)]


def test_absent_entry_is_the_logged_angle_bit_for_bit(missions):
    m = missions[0]
    plain, again = D.preprocess(m, None), D.preprocess(m, None, twist_smoothing={})
    assert len(plain) == 2
    assert all(np.array_equal(a.X, b.X) and np.array_equal(a.F, b.F, equal_nan=True) for a, b in zip(plain, again))
    assert not TwistSmoothing.from_config(None).active and TwistSmoothing().to_config() == {}


@pytest.mark.parametrize("entry, msg", [
    ({"window_s": -0.01}, "window_s must be"), ({"window_s": "9"}, "not a number"), ({"window_s": 5.0}, "window_s must be"),
    ({"window_s": 0.009, "polyorder": 7}, "polyorder"), ({"window": 0.009}, "unknown key"), ([0.009], "expected a mapping")])
def test_bad_entry_is_refused_naming_the_problem(entry, msg):
    with pytest.raises(ValueError, match=msg):
        TwistSmoothing.from_config(entry, "cfg.json twist_smoothing")


def test_the_written_entry_gives_discoverys_twist_in_the_twin_preprocessing(missions):
    from hd_ground.discovery.data import dataset_from_missions, with_smoothed_twist
    from hd_ground.discovery.pipeline import _twist_smoothing_entry

    entry = _twist_smoothing_entry(9, missions)
    assert entry == {"window_s": pytest.approx(0.009), "polyorder": 2}
    assert _twist_smoothing_entry(0, missions) == {}
    ds = with_smoothed_twist(dataset_from_missions(missions, ["a", "b"], retime_speeds=False), 9)
    N = float(missions[0].meta.gear_ratio)
    for i, m in enumerate(missions):
        segs = D.preprocess(m, None, twist_smoothing=entry)
        th_f = np.concatenate([s.X[:, 3] for s in segs])  # no decimation at fs_model None: the bag's rows
        phi_disc = ds.signals["phi"][ds.bag == i]
        th_m = np.concatenate([s.X[:, 0] for s in segs])
        assert np.allclose(th_f - th_m / N, phi_disc, rtol=0, atol=1e-12)
        logged = np.concatenate([s.X[:, 3] for s in D.preprocess(m, None)])
        assert np.max(np.abs(th_f - logged)) > 0.2 * STEP_16  # the smoothing did act, only on theta_f
        assert np.array_equal(np.concatenate([s.X[:, [0, 1, 2, 4]] for s in segs]),
                              np.concatenate([s.X[:, [0, 1, 2, 4]] for s in D.preprocess(m, None)]))


def test_fixed_lag_streaming_equals_the_batch_whatever_the_calls(missions):
    m = missions[1]
    X = D.mission_inputs(m)
    sm = TwistSmoothing(0.009)
    batch = sm.apply_X(X, m.fs)
    rng = np.random.default_rng(0)
    for _ in range(3):
        st = sm.streamer(m.fs, fixed_lag=True)
        assert isinstance(st, CentredSmoother) and st.lag == 4
        cuts = np.sort(rng.choice(np.arange(1, len(X)), 25, replace=False))
        outs = [st.step(part) for part in np.split(X, cuts)] + [st.flush()]
        got = np.vstack([o for o in outs if len(o)])
        assert got.shape == X.shape
        assert np.allclose(got, batch, rtol=0, atol=1e-12)
    # a segment not longer than the window keeps the logged angle, as the batch does
    st = sm.streamer(m.fs, fixed_lag=True)
    short = np.vstack([st.step(X[:6]), st.flush()])
    assert np.array_equal(short, X[:6]) and np.array_equal(sm.apply_X(X[:6], m.fs), X[:6])


def test_causal_streaming_smooths_the_quantised_angle():
    from tests.twin.synth import synth_mission

    m = synth_mission("EMA-T1", 0, fs=1000.0, duration=3.0, seed=0)
    q = _quantised(m)
    X, true = D.mission_inputs(q), np.asarray(m.theta_f)
    st = TwistSmoothing(0.009).streamer(q.fs)
    assert isinstance(st, CausalSmoother)
    got = np.vstack([st.step(X[i:i + 37]) for i in range(0, len(X), 37)])
    assert np.array_equal(got[:8, 3], X[:8, 3])  # before a whole window: as logged
    err = lambda x: np.sqrt(np.mean((x[50:] - true[50:]) ** 2))  # noqa: E731
    centred = TwistSmoothing(0.009).apply_X(X, q.fs)[:, 3]
    print(f"theta_f error against the true angle: logged {err(X[:, 3]):.3g}, causal {err(got[:, 3]):.3g}, "
          f"centred {err(centred):.3g} rad")
    # closer to the true angle than the counts; the end-of-window fit has the larger noise gain of the two
    assert err(centred) < err(got[:, 3]) < 0.9 * err(X[:, 3])
    assert np.array_equal(np.delete(got, 3, axis=1), np.delete(X, 3, axis=1))
    whole = TwistSmoothing(0.009).streamer(q.fs).step(X)
    assert np.allclose(whole, got, rtol=0, atol=1e-12)  # the same whatever the calls


def test_streamers_refuse_a_window_they_cannot_hold():
    """A window that is absurd at the input rate (a mislabelled or hostile bag's rate) is refused with a clear error,
    not allocated (the streamers' weights hold w^2 numbers); the batch smoother has no such weights."""
    from hd_twin.twistsmooth import MAX_STREAM_WINDOW

    sm = TwistSmoothing(0.5)
    for fixed_lag in (False, True):
        assert sm.streamer(1000.0, fixed_lag=fixed_lag).w == 501
        with pytest.raises(ValueError, match=f"more than the streaming twin takes \\({MAX_STREAM_WINDOW}\\)"):
            sm.streamer(1e6, fixed_lag=fixed_lag)
        with pytest.raises(ValueError, match="sample rate must be a positive number"):
            sm.streamer(float("nan"), fixed_lag=fixed_lag)


def test_window_in_samples_at_other_rates():
    assert window_samples(0.009, 1000.0) == 9 and window_samples(0.009, 250.0) == 3
    x = np.cumsum(np.random.default_rng(1).normal(size=50))
    assert np.array_equal(smooth_angle(x, None, 3), x)  # a quadratic through 3 samples: the identity
    with pytest.raises(ValueError, match="odd"):
        smooth_angle(x, None, 8)


def test_trained_twin_stores_the_entry_and_streams_on_the_smoothed_angle(tmp_path):
    """Training with an entry writes it to config.json; the ONNX runtime applies it at the input rate (its causal
    output equals the same network fed theta_f smoothed by CausalSmoother); without the entry the runtime is the
    one of every earlier model; `hdphm train --model-config` takes the entry."""
    from hd_twin.cli import _model_config
    from hd_twin.runtime import StreamingTwin
    from tests.twin.synth import synth_fleet, synth_mission, tiny_twin_with_and_without

    entry = {"window_s": 0.045, "polyorder": 2}  # 9 samples at the synthetic fleet's 200 Hz
    d_new, d_old = tiny_twin_with_and_without(tmp_path, "twist_smoothing", entry,
                                              [_quantised(m, 1e-3) for m in synth_fleet(2, 2, duration=2.0)])
    m = _quantised(synth_mission("EMA-NEW", 9, seed=123, duration=1.0), 1e-3)
    X = D.mission_inputs(m)
    new, old = StreamingTwin(d_new, fs_in=m.fs), StreamingTwin(d_old, fs_in=m.fs)
    q_new = np.concatenate([new.step(X[i:i + 64])["Q_red"] for i in range(0, len(X), 64)])
    q_ref = old.step(CausalSmoother(TwistSmoothing.from_config(entry), m.fs).step(X))["Q_red"]
    assert np.allclose(q_new, q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))
    old.reset(m.fs)
    assert not np.allclose(old.step(X)["Q_red"], q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))
    # fixed lag: the streamed outputs are those of the batch-smoothed inputs, half a window (4 rows at 200 Hz) late
    new.set_mode("fixed_lag")
    old.set_mode("fixed_lag")
    assert new.lag_samples == old.lag_samples + 4
    outs = [new.step(X[i:i + 50]) for i in range(0, len(X), 50)] + [new.flush()]
    q_fl = np.concatenate([o["Q_red"] for o in outs])
    ref = old.step(TwistSmoothing.from_config(entry).apply_X(X, m.fs))
    q_ref = np.concatenate([ref["Q_red"], old.flush()["Q_red"]])
    assert len(q_fl) == len(q_ref) and np.allclose(q_fl, q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))
    p = tmp_path / "c.json"
    p.write_text(json.dumps({"declared_effects": ["inertia"], "twist_smoothing": entry}))
    assert _model_config(str(p))["twist_smoothing"] == entry
    p.write_text(json.dumps({"declared_effects": ["inertia"], "twist_smoothing": {"window_s": -1}}))
    with pytest.raises(SystemExit, match="window_s must be"):
        _model_config(str(p))
