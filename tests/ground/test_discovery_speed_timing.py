"""The logged speed's timing is identified from the data, not assumed (issue 10).

A drive logs its own speed estimate: the encoder angle differenced and low-pass filtered. Discovery identifies
that estimate's delay behind the angle's own rate by least squares and re-times the speed before any friction
term sees it (a Stribeck curve fitted on lagged speeds is wrong at constant speed). Synthetic missions written
here (numpy only): the delay of a known discrete filter is recovered, the re-timed speed is closer to the true
rate, a speed that is already on the angle's time base is left alone, and the target's own cross-validated
baseline error decides whether the re-timed speed is used (the torque may be on either time base).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from hd_ground.discovery.data import retime_speed, speed_lag, speed_timing

FS = 1000.0


def _mission(seed: int, f_c: float | None, bits: int = 18, duration: float = 6.0):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * FS)) / FS
    amp, freq, ph = rng.uniform(1.0, 3.0, 3), np.array([0.4, 1.3, 3.1]) * rng.uniform(0.8, 1.2, 3), rng.uniform(0, 6, 3)
    theta = (amp[:, None] * np.sin(2 * np.pi * freq[:, None] * t + ph[:, None])).sum(0)
    rate = (amp[:, None] * 2 * np.pi * freq[:, None] * np.cos(2 * np.pi * freq[:, None] * t + ph[:, None])).sum(0)
    q = 2 * np.pi / 2 ** bits
    theta_q = np.round(theta / q) * q
    if f_c is None:  # a speed on the angle's time base (a simulator's true speed)
        omega = rate + rng.normal(0, 0.01, len(t))
    else:  # the drive's estimate: backward difference of the quantised angle, first-order low-pass
        x = np.r_[rate[0], np.diff(theta_q) * FS]
        a = np.exp(-2 * np.pi * f_c / FS)
        omega = np.empty_like(x)
        omega[0] = x[0]
        for k in range(1, len(x)):
            omega[k] = a * omega[k - 1] + (1 - a) * x[k]
    m = SimpleNamespace(t=t, theta_m=theta_q, omega_m=omega, theta_f=theta_q / 50, omega_f=omega / 50,
                        segment=np.zeros(len(t), int), n=len(t))
    return m, rate


@pytest.mark.parametrize("f_c", [50.0, 150.0])
def test_filter_delay_recovered_and_speed_retimed(f_c):
    ms = [_mission(s, f_c) for s in range(3)]
    tau, se = speed_lag([m for m, _ in ms], "omega_m", "theta_m")
    a = np.exp(-2 * np.pi * f_c / FS)
    expected = (a / (1 - a) + 0.5) / FS  # low-frequency delay of the discrete filter + the backward difference
    assert se > 0 and abs(tau) > 3 * se
    assert tau == pytest.approx(expected, rel=0.05)
    lags, notes = speed_timing([m for m, _ in ms])
    assert lags["omega_m"] == pytest.approx(tau) and any("re-timed" in n for n in notes)
    m, rate = ms[0]
    new = retime_speed(m.omega_m, m.t, m.segment, lags["omega_m"], 0.02)
    inner = slice(50, -50)
    assert np.std((new - rate)[inner]) < 0.3 * np.std((m.omega_m - rate)[inner])


def test_speed_on_the_angle_time_base_is_left_alone():
    ms = [_mission(s, None) for s in range(3)]
    lags, notes = speed_timing([m for m, _ in ms])
    assert "omega_m" not in lags and "omega_f" not in lags, notes


def _datasets(torque_on: str, seed: int = 0):
    """Four bags of fast reversals; the logged speed is a drive estimate (50 Hz filter); the torque's friction
    acts on the true speed (``torque_on="true"``) or on the logged one (a torque logged with the same delay)."""
    from hd_ground.discovery.data import Dataset, _derivative

    ms = [_mission(seed + i, 50.0, duration=4.0) for i in range(4)]
    tau, _ = speed_lag([m for m, _ in ms], "omega_m", "theta_m")
    rng = np.random.default_rng(seed)
    cols_l, cols_r = {}, {}
    for m, rate in ms:
        seg = m.segment
        w_r = retime_speed(m.omega_m, m.t, seg, tau, 0.02)
        w_t = rate if torque_on == "true" else m.omega_m
        a_t = _derivative(w_t, m.t, seg, 0.02)
        y = 0.01 * a_t + 1.0 * np.tanh(w_t / 0.5) + 0.01 * w_t + rng.normal(0, 0.02, m.n)
        for cols, w in ((cols_l, m.omega_m), (cols_r, w_r)):
            for k, v in (("theta_m", m.theta_m), ("omega_m", w), ("alpha_m", _derivative(w, m.t, seg, 0.02)),
                         ("tau_m", y)):
                cols.setdefault(k, []).append(v)
    n = ms[0][0].n
    bag = np.repeat(np.arange(4), n)
    frac = np.tile(np.arange(n) / (n - 1), 4)
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    t = np.tile(ms[0][0].t, 4)

    def ds(cols, lags):
        return Dataset({k: np.concatenate(v) for k, v in cols.items()}, bag, block, frac, t, bag.copy(),
                       [f"bag{i}" for i in range(4)], 100.0, 0.1, speed_lags=lags)
    return ds(cols_l, {}), ds(cols_r, {"omega_m": tau}), bag == 3


@pytest.mark.parametrize("torque_on", ["true", "logged"])
def test_the_target_decides_whether_retimed_speeds_are_used(torque_on):
    from hd_ground.discovery.core import choose_speed_timing

    ds_l, ds_r, ho = _datasets(torque_on)
    ds, st = choose_speed_timing(ds_l, ds_r, ho)
    if torque_on == "true":  # the friction acts on the speed at the angle's instants: re-timing helps
        assert ds is ds_r and "; used" in st, st
    else:  # the torque is on the logged speed's time base: re-timing would hurt, the logged speed is kept
        assert ds is ds_l and "as logged" in st and ds.speed_lags == {}, st
