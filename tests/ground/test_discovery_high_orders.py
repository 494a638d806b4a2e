"""Discovery (issue 10, thirty-seventh pass): order lines above what the fastest rows sample.

The order spectrum's grid used to end at the order the 95th-percentile angle step samples 4 times per period: on
a 1 kHz log of a motor at 140 rad/s, order 11. A PMSM's torque ripple sits at 6 p electrical orders (30 mechanical
for 5 pole pairs), so it was never a candidate, though the slower rows sample it well. Each order is now integrated
over the rows that sample it (``spectrum.order_spectrum``), the grid reaches the order whose rows still travel
two revolutions, and lines are judged against each order's own noise level.

Synthetic motor written here (numpy only, no hd_sim): the shaft torque J alpha + T_C tanh(omega / EPS) + b omega +
Q / N is produced by k_t i_q (1 + R cos(30 theta_m + PHI)), while the drive logs tau_m = k_t i_q (PHYSICS.md's
current ripple); four bags at 500 Hz, the motor at up to 15-35 rad/s (order 30 is sampled 4 times per period below
26 rad/s only; faster, the logger's mean over its period attenuates it), logged as a drive logs them. The ripple
must be named as current ripple at order 30 with its amplitude; clean data gives no position-periodic finding at
all.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal
from hd_ground.discovery.spectrum import analyse_orders

from .synthetic import dataset, log_motor_with_load

FS, SUB, T_BAG, NR, KT = 500.0, 40, 6.0, 50.0, 0.3
J, B, EPS, T_C = 0.01, 0.02, 0.5, 0.05
R, K, PHI = 0.02, 30.0, 0.6
AMPS = (15.0, 35.0, 20.0, 30.0)  # rad/s, per bag; the last held out


def _plant(ripple: float = R, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    tf = np.arange(n * SUB) / (FS * SUB)
    t = np.arange(n) / FS
    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "tau_m", "Q_red", "Q_red_over_N", "i_q")}
    for i, a in enumerate(AMPS):
        w = a * np.sin(2 * np.pi * (0.3 + 0.07 * i) * tf) + 0.2 * a * np.sin(2 * np.pi * (1.7 + 0.4 * i) * tf)
        th = np.cumsum(w) / (FS * SUB)
        Q = 40.0 * np.sin(2 * np.pi * (0.23 + 0.05 * i) * tf + i) + 60.0
        shaft = J * np.gradient(w, tf) + T_C * np.tanh(w / EPS) + B * w + Q / NR
        i_q = shaft / (KT * (1.0 + ripple * np.cos(K * th + PHI)))
        c = log_motor_with_load(th, w, i_q, Q, rng, kt=KT, ratio=NR, fs=FS, sub=SUB)  # logged torque: k_t,nom i_q
        for k, v in c.items():
            cols[k].append(v)
    return dataset(cols, t, ratio=NR)


def test_a_line_above_the_fast_rows_order_is_found_on_the_slow_rows():
    rng = np.random.default_rng(3)
    fs, n = 1000.0, 40000
    t = np.arange(n) / fs
    w = 80.0 * np.sin(2 * np.pi * 0.1 * t) ** 3  # mostly fast, slow around the reversals
    th = np.cumsum(w) / fs
    r = 0.05 * np.sin(K * th + 0.3) + rng.normal(0, 0.1, n)
    spec = analyse_orders(r, th, "theta_m")
    assert spec.orders[-1] > K and K in spec.peaks, (spec.orders[-1], spec.peaks)
    i = int(np.argmin(np.abs(spec.orders - K)))
    assert spec.amplitude[i] == pytest.approx(0.05, rel=0.25)
    # white noise alone: no line, though the high orders rest on fewer rows
    assert analyse_orders(rng.normal(0, 0.1, n), th, "theta_m").peaks == []


def test_current_ripple_at_order_30_is_named_with_its_amplitude():
    ds, ho = _plant()
    # the grid's old top (4 samples per period at the 95th-percentile step) is below the ripple's order
    step = np.abs(np.diff(ds.signals["theta_m"][~ho]))
    assert 2 * np.pi / (4 * np.quantile(step[step > 0], 0.95)) < K
    r = discover_signal(ds, "tau_m", ho)
    rip = [e for e in r.effects if e["name"] == "current_ripple" and e["order"] == K]
    assert rip, (r.effects, r.cv_trace)
    # the logged torque is k_t i_q = shaft / (1 + R cos): its ripple is -R k_t i_q cos(...), amplitude k_t R per ampere
    assert rip[0]["parameters"]["k_t_r_30"] / KT == pytest.approx(R, rel=0.15), rip[0]["parameters"]
    assert r.error_after["rmse"] < 0.85 * r.error_before["rmse"], (r.error_before, r.error_after)


def test_clean_motor_has_no_position_periodic_finding():
    ds, ho = _plant(ripple=0.0)
    r = discover_signal(ds, "tau_m", ho)
    assert not [e for e in r.effects if e["variable"] == "theta_m"], r.effects
