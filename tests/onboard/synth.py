"""Small synthetic missions for the onboard tests, generated from the twin's own physics.

Not the plant (hd_sim): a consistent data set whose expected response is known,
so the core's mechanics (residuals, detector, conditioning) are tested in
isolation. Output flap follows a sinusoid; the aerodynamic load is
K_aero theta_f; the motor torque is what the quasi-static physics needs plus
noise; a fault adds ``fault_dT`` N*m of input friction from ``fault_at`` s.
"""
from __future__ import annotations

import numpy as np

from hd_bag.mission import Mission, MissionMeta
from hd_twin import physics as ph


def make_mission(duration=20.0, fs=1000.0, fault_at=None, fault_dT=0.3, seed=0, actuator="EMA-T1", noise=0.02):
    rng = np.random.default_rng(seed)
    p = ph.TwinParams.from_yaml()
    N = p.N
    n = int(duration * fs)
    t = np.arange(n) / fs
    A, f = np.deg2rad(10.0), 0.5
    theta_f = A * np.sin(2 * np.pi * f * t) + 0.3 * A * np.sin(2 * np.pi * 1.7 * f * t)
    omega_f = np.gradient(theta_f, t)
    alpha_f = np.gradient(omega_f, t)
    omega_m, alpha_m = N * omega_f, N * alpha_f
    Q_load = 300.0 * theta_f + 5.0 * np.sin(2 * np.pi * 0.2 * t)
    T_f = ph.input_friction(np, p, ["coulomb_friction", "viscous_friction"], omega_m)
    tau_m = (Q_load + p.J_CS * alpha_f) / (N * 0.8) + T_f + p.J_in * alpha_m
    if fault_at is not None:
        tau_m = tau_m + np.where(t >= fault_at, fault_dT * np.tanh(omega_m / p.eps_omega), 0.0)
    # the measured output torque is what the twin's physics makes of this motor torque
    # (a fault is extra input friction the twin does not know: it shows as a residual)
    tau_healthy = tau_m - (np.where(t >= fault_at, fault_dT * np.tanh(omega_m / p.eps_omega), 0.0) if fault_at is not None else 0.0)
    Q_red = ph.quasi_static_Q_red(p, ph.DEFAULT_EFFECTS, tau_healthy, omega_m, None, theta_m_dd=alpha_m, theta_f_dd=alpha_f)
    theta_m = N * (theta_f + Q_red / p.K_out)  # wind-up: the motor side leads under positive Q_red (as the plant)
    tau_m = tau_m + noise * rng.standard_normal(n)
    Q_red = Q_red + 0.5 * rng.standard_normal(n)
    meta = MissionMeta(actuator, 0, 0.0, N, p.k_t)
    t_cmd = t[::10]
    return Mission(meta=meta, t=t, theta_m=theta_m, theta_f=theta_f, omega_m=omega_m, omega_f=omega_f,
                   tau_m=tau_m, Q_red=Q_red, t_cmd=t_cmd, theta_ref=np.interp(t_cmd, t, theta_f),
                   temperatures={"gearbox": (t[::1000], np.full(len(t[::1000]), 30.0))}, t0_ns=1_700_000_000_000_000_000)
