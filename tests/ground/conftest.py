"""Synthetic actuator missions for the discovery tests.

A small independent plant (not hd_sim): output motion = two sinusoids, motor
torque = J_eq alpha_m + Q_red/(N eta) + Coulomb + viscous friction + the
undeclared effects switched on, plus sensor noise. The truth is known to the
test only (it is never written into the bag).
"""

import numpy as np
import pytest

from hd_bag.mission import Mission, MissionMeta

N = 100.0
K_T = 0.1


def synth_mission(seed=0, *, T=12.0, fs=1000.0, effects=None, offset=0.0, one_way=False, const_speed=False,
                  noise=0.01, index=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, T, 1.0 / fs)
    ph = rng.uniform(0, 2 * np.pi, 2)
    if const_speed:
        th_f = 0.5 * t
    else:
        th_f = 0.3 * np.sin(2 * np.pi * 0.3 * t + ph[0]) + 0.1 * np.sin(2 * np.pi * 0.77 * t + ph[1])
    if one_way and not const_speed:
        th_f = th_f + 0.5 * t
    w_f = np.gradient(th_f, t)
    a_f = np.gradient(w_f, t)
    th_m, w_m, a_m = N * th_f, N * w_f, N * a_f
    Q = 50 * np.sin(2 * np.pi * 0.2 * t + ph[0]) + 20 * w_f
    sg = np.tanh(w_m / 0.05)
    tau = 3e-4 * a_m + Q / (N * 0.8) + 0.08 * sg + 3e-5 * w_m
    e = effects or {}
    if "position_periodic_friction" in e:
        F, k, rho = e["position_periodic_friction"]
        tau = tau + F * np.sin(k * th_m + rho) * sg
    if "position_periodic_torque" in e:
        A, k, psi = e["position_periodic_torque"]
        tau = tau + A * np.sin(k * th_m + psi)
    if "cogging_torque" in e:
        A, k, psi = e["cogging_torque"]
        tau = tau + A * np.sin(k * th_m + psi)
    if "stribeck_friction" in e:
        dT, ws = e["stribeck_friction"]
        tau = tau + dT * np.exp(-np.abs(w_m) / ws) * sg
    if "load_dependent_friction" in e:
        tau = tau + e["load_dependent_friction"] * np.abs(Q) * sg
    tau_meas = tau + noise * rng.normal(size=len(t))
    meta = MissionMeta("EMA-TEST", index, 0.0, N, K_T, source="simulation")
    tt = t[::100]
    return Mission(meta, t, th_m + offset, th_f, w_m + 0.01 * rng.normal(size=len(t)), w_f, tau_meas,
                   Q + 0.1 * rng.normal(size=len(t)), t, th_f, {"gearbox": (tt, 25.0 + 0 * tt)})


@pytest.fixture
def make_mission():
    return synth_mission
