"""The derivative window of the logged speed's re-timing is identified from the data (issue 10, branch disc31 pass).

A drive logs its own speed estimate (the quantised encoder angle differenced and low-pass filtered: a delay tau);
discovery re-times it, ``omega + tau omega'``, with omega' a quadratic Savitzky-Golay derivative. Its window is a
filter bandwidth: a long one lags a fast reversal (the re-timed speed is wrong where the friction flips), a short
one differentiates the speed's noise. Synthetic missions written here (numpy only, no hd_sim), the friction acting on
the true speed at the angle's instants, so the right window is known: the one whose re-timed speed is closest to the
true speed. ``core.choose_retime_window`` must move off the 20 ms default where reversals take a few ms (and pick a
window whose re-timed speed is near the best candidate's), and keep the default on slow motion with a noisy speed
(nothing to gain, noise to lose). The identification is opt-in (``Options.retime_window="identify"``, ``hdphm discover
--retime-window identify``): on the bench it moves the raw Stribeck profile's held-out error both ways
(docs/DISCOVERY_PASSES.md, branch disc31's pass).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from hd_ground.discovery.core import Options, choose_retime_window
from hd_ground.discovery.data import Dataset, _derivative, retime_speed, speed_lag

FS, N_BAGS, DUR = 1000.0, 4, 4.0
IDENTIFY = Options(retime_window="identify")
J, T_C, EPS, B = 0.002, 0.5, 0.3, 0.01


def _mission(seed: int, fast: bool):
    """One bag: true speed ``rate`` (fast: near-square reversals of ~3 ms; slow: a smooth sweep), the drive's
    estimate (backward difference of an 18-bit angle, 60 Hz first-order low-pass: delay ~3 ms; slow: plus white
    noise 0.05 rad/s), and a torque J alpha + T_C tanh(rate / EPS) + B rate + noise on the true speed."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(DUR * FS)) / FS
    f = rng.uniform(1.5, 2.5)
    if fast:
        rate = 3.0 * np.tanh(np.sin(2 * np.pi * f * t + seed) / 0.04) + 0.5 * np.sin(2 * np.pi * 0.3 * t)
    else:
        rate = 3.0 * np.sin(2 * np.pi * 0.3 * f * t + seed)
    theta = np.cumsum(rate) / FS
    q = 2 * np.pi / 2 ** 18
    theta_q = np.round(theta / q) * q
    x = np.r_[rate[0], np.diff(theta_q) * FS]
    a = np.exp(-2 * np.pi * 60.0 / FS)
    omega = np.empty_like(x)
    omega[0] = x[0]
    for k in range(1, len(x)):
        omega[k] = a * omega[k - 1] + (1 - a) * x[k]
    if not fast:
        omega = omega + rng.normal(0, 0.05, len(t))
    tau = J * np.gradient(rate, t) + T_C * np.tanh(rate / EPS) + B * rate + rng.normal(0, 0.01, len(t))
    m = SimpleNamespace(t=t, theta_m=theta_q, omega_m=omega, segment=np.zeros(len(t), int), n=len(t))
    return m, rate, tau


def _make(fast: bool):
    bags = [_mission(10 * fast + i, fast) for i in range(N_BAGS)]
    n = bags[0][0].n
    bag = np.repeat(np.arange(N_BAGS), n)
    frac = np.tile(np.arange(n) / (n - 1), N_BAGS)
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    t = np.tile(bags[0][0].t, N_BAGS)

    def make(win: float) -> Dataset:
        lag, _ = speed_lag([m for m, _, _ in bags], "omega_m", "theta_m", window_s=win)
        cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "tau_m")}
        for m, _, y in bags:
            w = retime_speed(m.omega_m, m.t, m.segment, lag, win)
            for k, v in (("theta_m", m.theta_m), ("omega_m", w), ("alpha_m", _derivative(w, m.t, m.segment, 0.02)),
                         ("tau_m", y)):
                cols[k].append(v)
        return Dataset({k: np.concatenate(v) for k, v in cols.items()}, bag, block, frac, t, bag.copy(),
                       [f"bag{i}" for i in range(N_BAGS)], 50.0, 0.1, speed_lags={"omega_m": lag},
                       speed_window_s=win)

    def speed_error(ds: Dataset) -> float:  # RMS of the re-timed speed against the true one (the known answer)
        return float(np.sqrt(np.mean((ds.signals["omega_m"] - np.concatenate([r for _, r, _ in bags])) ** 2)))
    return make, speed_error, bag == N_BAGS - 1


@pytest.mark.parametrize("fast", [True, False])
def test_retime_window_identified_where_the_reversals_need_it(fast):
    make, speed_error, ho = _make(fast)
    ds0 = make(0.02)
    ds, st = choose_retime_window(make, ds0, ho, IDENTIFY)
    assert st.startswith("speed re-timing window:"), st
    errs = {w: speed_error(make(w)) for w in (0.005, 0.009, 0.017, 0.02, 0.033)}
    best = min(errs, key=errs.get)
    if fast:
        # the known answer: a short window re-times the fast reversals better than the default ...
        assert best < 0.02 and errs[best] < 0.7 * errs[0.02], errs
        # ... and the fit bags' CV finds one: used, carried on the dataset, its speed near the best candidate's
        assert ds is not ds0 and "; used" in st, st
        assert ds.speed_window_s < 0.02 and ds.speed_lags["omega_m"] > 0
        assert speed_error(ds) < 1.15 * errs[best], (ds.speed_window_s, errs)
    else:
        # slow motion, noisy speed: the default is kept (a short window only adds differentiated noise)
        assert errs[0.005] > errs[0.02], errs
        assert ds is ds0 and "is kept" in st and ds.speed_window_s == 0.02, st


def test_retime_window_default_mode_tries_nothing():
    make, _, ho = _make(True)
    ds0 = make(0.02)
    for opt in (Options(), Options(retime_window="default")):  # the default (opt-in: see the module docstring)
        ds, st = choose_retime_window(make, ds0, ho, opt)
        assert ds is ds0 and st == ""


def test_identified_window_is_carried_to_the_twin():
    """The twin's config entry carries the window the delays were identified and applied with, and the twin's batch
    re-timing (``SpeedTiming.apply_X``) reproduces discovery's re-timed speed with it."""
    from hd_ground.discovery.pipeline import _speed_timing_entry
    from hd_twin.speedtiming import SpeedTiming

    make, _, ho = _make(True)
    ds, _ = choose_retime_window(make, make(0.02), ho, IDENTIFY)
    m, _, _ = _mission(10, True)  # bag 0 of the fast plant
    entry = _speed_timing_entry(dict(ds.speed_lags), [_mission(10 + i, True)[0] for i in range(N_BAGS)],
                                ds.speed_window_s)
    assert entry["window_s"] == pytest.approx(ds.speed_window_s) and entry["omega_m"]["se"] > 0, entry
    st = SpeedTiming.from_config(entry)
    X = np.zeros((m.n, 7))
    X[:, 1] = m.omega_m
    np.testing.assert_allclose(st.apply_X(X, m.t)[:, 1], ds.signals["omega_m"][ds.bag == 0], rtol=0, atol=1e-12)
