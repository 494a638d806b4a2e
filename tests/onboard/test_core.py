"""Onboard core: detector arithmetic, conditioning and end-to-end flags on synthetic missions."""

import numpy as np
import pytest

from tests.onboard.synth import make_mission  # noqa: E402

from hd_onboard.batch import run_mission  # noqa: E402
from hd_onboard.config import OnboardConfig  # noqa: E402
from hd_onboard.core import OnboardCore  # noqa: E402
from hd_onboard.residuals import RESIDUAL_COLUMNS  # noqa: E402
from hd_onboard.detectors.ewma import ChannelThreshold, ewma  # noqa: E402
from hd_onboard.detectors.levels import ERROR, OK, WARN, LevelLatch, run_lengths  # noqa: E402
from hd_ground.thresholds import actuator_thresholds, channel_threshold, persistent_peak  # noqa: E402


def test_ewma_matches_loop_and_skips_nan():
    rng = np.random.default_rng(1)
    z = rng.standard_normal(500)
    z[[10, 11, 300]] = np.nan
    lam, e0 = 0.05, 0.7
    ref, e = [], e0
    for v in z:
        if np.isfinite(v):
            e = (1 - lam) * e + lam * v
        ref.append(e)
    got = np.concatenate([ewma(z[:123], lam, e0), ewma(z[123:], lam, ref[122])])
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)


def test_run_lengths_with_carry():
    b = np.array([1, 1, 0, 1, 1, 1, 0], bool)
    np.testing.assert_array_equal(run_lengths(b, 3), [4, 5, 0, 1, 2, 3, 0])


def test_latch_holds_and_orders_levels():
    L = LevelLatch(hold_s=0.5)
    t = np.arange(10) * 0.1
    w = np.zeros(10, bool); e = np.zeros(10, bool)
    w[2] = True; e[3] = True
    lev = L.step(t, w, e)
    assert lev[:2].tolist() == [OK, OK] and lev[2] == WARN and lev[3] == ERROR
    assert lev[7] == ERROR and lev[8] == WARN or lev[8] == OK
    assert L.step(np.array([5.0]), np.zeros(1, bool), np.zeros(1, bool))[0] == OK


def test_threshold_validation_refuses_absurd():
    with pytest.raises(ValueError, match="sigma"):
        ChannelThreshold(0.0, 0.0, 1, 2).validate("x")
    with pytest.raises(ValueError, match="h_warn"):
        ChannelThreshold(0.0, 1.0, 5, 2).validate("x")
    with pytest.raises(ValueError, match="finite"):
        ChannelThreshold(float("nan"), 1.0, 1, 2).validate("x")


def test_persistent_peak():
    a = np.array([0, 5, 0, 3, 3, 3, 0.0])
    assert persistent_peak(a, 1) == 5 and persistent_peak(a, 3) == 3


def _old_threshold_arithmetic(segs, fs, tau, pers, wm, em, hw, he, floor=0.0):
    """The arithmetic both former copies (ground channel_threshold, onboard calibrate_channel) ran."""
    from hd_onboard.detectors.ewma import ewma
    fin = np.concatenate(segs)
    fin = fin[np.isfinite(fin)]
    mu = float(np.median(fin))
    sigma = float(1.4826 * np.median(np.abs(fin - mu)))
    sigma = max(sigma, floor)
    lam = min(1.0, 1.0 / (tau * fs))
    peak = 0.0
    for s in segs:
        e = ewma((s - mu) / sigma, lam, 0.0)
        e = np.where(np.isfinite(s), np.abs(e), np.nan)
        e[: int(tau * fs)] = np.nan
        peak = max(peak, persistent_peak(e, max(1, int(round(pers * fs)))))
    h_warn = max(hw, wm * peak)
    return mu, sigma, h_warn, max(he, em * peak, 1.5 * h_warn)


def test_onboard_and_ground_thresholds_are_one_function():
    """Self-calibration (one warm-up segment) and ground thresholds give identical lines on the same
    data, equal to the arithmetic both ran before they were merged; the scale floor is onboard-only."""
    from hd_onboard.calibration import calibrate_channel

    rng = np.random.default_rng(7)
    r = 0.3 + 0.05 * rng.standard_t(4, 3000)
    r[100:110] = np.nan
    r[2000:2300] += 0.4  # a transient: the peak must come from it
    kw = dict(fs=1000.0, ewma_tau_s=0.1, persistence_s=0.05, warn_margin=1.5, error_margin=3.0,
              min_h_warn=3.0, min_h_error=6.0)
    g = channel_threshold([r], **kw)
    o = calibrate_channel(r, **kw)
    got_g = (g.mu, g.sigma, g.h_warn, g.h_error)
    assert got_g == (o.mu, o.sigma, o.h_warn, o.h_error)
    ref = _old_threshold_arithmetic([r], 1000.0, 0.1, 0.05, 1.5, 3.0, 3.0, 6.0)
    assert np.allclose(got_g, ref, rtol=1e-12, atol=0)
    assert g.h_warn > 3.0  # the transient lifted the line above the floor value
    # several segments (ground): pooled mu/sigma, largest per-segment peak
    r2 = 0.3 + 0.05 * rng.standard_normal(1500)
    g2 = channel_threshold([r, r2], **kw)
    assert np.allclose((g2.mu, g2.sigma, g2.h_warn, g2.h_error),
                       _old_threshold_arithmetic([r, r2], 1000.0, 0.1, 0.05, 1.5, 3.0, 3.0, 6.0), rtol=1e-12, atol=0)
    # the floor (onboard): sigma raised, lines from the floored scale
    o2 = calibrate_channel(r, sigma_floor=1.0, **kw)
    assert o2.sigma == 1.0 and "sigma floor" in o2.source
    assert np.allclose((o2.mu, o2.sigma, o2.h_warn, o2.h_error),
                       _old_threshold_arithmetic([r], 1000.0, 0.1, 0.05, 1.5, 3.0, 3.0, 6.0, floor=1.0), rtol=1e-12, atol=0)


def test_healthy_no_flag_fault_flags_quickly():
    h = run_mission(make_mission(seed=2))
    assert h["max_level"] == OK and h["onset_s"] is None
    f = run_mission(make_mission(seed=3, fault_at=12.0))
    assert f["max_level"] == ERROR
    assert 12.0 <= f["onset_s"] < 12.5, f["onset_s"]
    assert f["table"].shape[1] == len(RESIDUAL_COLUMNS)
    assert len(f["windows"]) == 20


def test_ground_thresholds_then_no_false_alarm_on_other_healthy():
    res = [run_mission(make_mission(seed=s)) for s in (10, 11)]
    th = actuator_thresholds(res)
    assert set(th) == {"Q_red", "twist"} and th["Q_red"].h_warn >= 3.0
    other = run_mission(make_mission(seed=12), thresholds=th)
    assert other["max_level"] == OK
    fault = run_mission(make_mission(seed=13, fault_at=4.0), thresholds=th)
    assert fault["max_level"] >= WARN and fault["onset_s"] >= 4.0


def test_block_size_does_not_change_results():
    m = make_mission(duration=8.0, seed=4, fault_at=6.0)
    a = run_mission(m, block=1000)
    b = run_mission(m, block=37)
    np.testing.assert_allclose(a["table"], b["table"], rtol=1e-9, atol=1e-9, equal_nan=True)


def test_conditioning_nan_dropout_out_of_order():
    m = make_mission(duration=10.0, seed=5)
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    V[6000:6005, 4] = np.nan  # short NaN burst
    keep = np.ones(len(stamps), bool); keep[7000:7500] = False  # 0.5 s dropout
    order = np.arange(len(stamps)); order[8000], order[8001] = 8001, 8000  # swapped pair
    s2, V2 = stamps[keep][order[order < keep.sum()]], V[keep][order[order < keep.sum()]]
    core = OnboardCore(gear_ratio=m.meta.gear_ratio)
    out = [core.push(s2[a:a + 333], V2[a:a + 333]) for a in range(0, len(s2), 333)]
    h = core.health
    assert h.n_nan == 5 and h.n_dropped_order == 1 and h.n_resets >= 1 and h.n_missing >= 499
    assert max(o.level for o in out) == OK
    tab = np.concatenate([o.table for o in out])
    assert np.all(np.diff(tab[:, 0]) > 0)
    assert np.isnan(tab[np.searchsorted(tab[:, 0], stamps[6002] * 1e-9), 3])


def test_bad_input_shapes_and_config():
    core = OnboardCore(gear_ratio=101.0)
    with pytest.raises(ValueError, match="samples"):
        core.push(np.zeros(3, np.int64), np.zeros((3, 5)))
    with pytest.raises(ValueError, match="window_s"):
        OnboardConfig(window_s=-1.0).validate()
