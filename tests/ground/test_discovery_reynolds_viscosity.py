"""Discovery (issue 10, twenty-eighth pass): a lubricant's viscosity falls exponentially with temperature.

Synthetic motor written here (numpy only, no hd_sim): J alpha + T_C tanh(omega / EPS) + b(T) omega with Reynolds'
law b(T) = B exp(-BETA (T - 25)), each bag warming by 20 K from its own start (the held-out bag colder than the fit
bags, as plant2's missions at fresh seeds 7300 / 8500 are, where the linear law fitted on warm missions missed by
20-35 %). Simulated at 20 kHz, logged at 500 Hz as a drive logs it (``synthetic.log_as_drive``); four bags, the last
held out. The temperature family's preferred reading is Reynolds' law with its exponent identified by the CV
profile; it must find BETA, beat the linear law on the held-out bag, reduce to it where the truth is linear, and
find nothing where the viscosity does not change.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal

from .synthetic import dataset, log_as_drive

FS, SUB, T_BAG, NR = 500.0, 40, 6.0, 50.0
J, B, EPS, T_C, BETA = 0.01, 0.02, 0.5, 0.05, 0.03
T_START = (20.0, 35.0, 10.0, -5.0)  # the last bag (held out) starts colder than any fit bag


def _plant(b_of_T, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    tf = np.arange(n * SUB) / (FS * SUB)
    t = np.arange(n) / FS
    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "tau_m", "temperature")}
    for i, t0 in enumerate(T_START):
        w = (6.0 + i) * np.sin(2 * np.pi * (0.3 + 0.07 * i) * tf) + 2.0 * np.sin(2 * np.pi * (1.7 + 0.4 * i) * tf)
        th = np.cumsum(w) / (FS * SUB)
        temp = t0 + 20.0 * tf / tf[-1]
        tau = J * np.gradient(w, tf) + T_C * np.tanh(w / EPS) + b_of_T(temp) * w
        c = log_as_drive(th, w, tau, FS, SUB, rng)
        c["temperature"] = np.round((temp[::SUB] + rng.normal(0, 0.05, n)) / 0.1) * 0.1
        for k, v in c.items():
            cols[k].append(v)
    return dataset(cols, t, ratio=NR)


def _temperature_term(r):
    return [e for e in r.effects if e["name"] == "temperature_dependent_friction"]


def test_reynolds_law_found_with_its_exponent_and_it_extrapolates():
    ds, ho = _plant(lambda T: B * np.exp(-BETA * (T - 25.0)))
    r = discover_signal(ds, "tau_m", ho)
    term = _temperature_term(r)
    assert term, r.cv_trace
    p = term[0]["parameters"]
    assert p["beta"] == pytest.approx(BETA, rel=0.2), p
    # the linear law's held-out error on the same rows: least squares of the baseline + omega (T - T_ref) on the fit
    # bags (the alternative the family had before this pass)
    s = ds.signals
    fit = ~ho
    dT = s["temperature"] - p["T_ref"]
    X = np.column_stack([s["alpha_m"], np.tanh(s["omega_m"] / EPS), s["omega_m"], s["omega_m"] * dT,
                         np.tanh(s["omega_m"] / EPS) * dT])
    coef = np.linalg.lstsq(X[fit], s["tau_m"][fit], rcond=None)[0]
    lin = float(np.sqrt(np.mean((s["tau_m"] - X @ coef)[ho] ** 2)))
    assert r.error_after["rmse"] < 0.8 * lin, (r.error_after, lin)


def test_a_linear_law_is_read_as_one():
    # b rising linearly with T (not a lubricant's law): whichever reading the family keeps must give that b(T)
    ds, ho = _plant(lambda T: B * (1.0 + 0.01 * (T - 25.0)))
    r = discover_signal(ds, "tau_m", ho)
    term = _temperature_term(r)
    assert term, r.cv_trace
    p = term[0]["parameters"]
    assert p["db_dT"] == pytest.approx(0.01 * B, rel=0.25), p


def test_constant_viscosity_no_temperature_finding():
    ds, ho = _plant(lambda T: B + 0.0 * T)
    r = discover_signal(ds, "tau_m", ho)
    assert not _temperature_term(r), r.effects
