"""Synthetic discovery datasets shared by the tests (numpy only, no hd_sim).

``stribeck_design``: the Stribeck friction's columns for a shape search; ``log_as_drive``: a fine-step motor
simulation logged as a drive logs it; ``dataset``: per-bag columns as a discovery Dataset, five blocks per bag, the last bag held out. ``torsion_plant``,
the twist-side Q_red plant: four 8 s bags at 500 Hz (the last held out, five blocks each): a motor sweep theta_m = 40 sin(2 pi f_i t), a wind-up
w of a load sweep plus a 1.7 Hz ripple, and Q_red = spring(x) + 50 w' + N(0, 3 N*m) with x = w - e(theta_m) the
spring's own deflection (e the position error inside it, none by default).
"""

import numpy as np

from hd_ground.discovery.data import Dataset
from hd_twin.speedtiming import sg2_derivative

FS, T_BAG, N_BAGS, N = 500.0, 8.0, 4, 80.0


def dataset(cols: dict, t: np.ndarray, ratio: float = N) -> tuple[Dataset, np.ndarray]:
    """The bags' columns (a list per signal, one array per bag on the common time ``t``) as a discovery Dataset with
    gear ratio ``ratio``, and its held-out mask (the last bag)."""
    sig = {k: np.concatenate(v) for k, v in cols.items()}
    n, n_bags = len(t), len(next(iter(cols.values())))
    bag = np.repeat(np.arange(n_bags), n)
    frac = np.tile(t / t[-1], n_bags)
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    ds = Dataset(sig, bag, block, frac, np.tile(t, n_bags), bag.copy(), [f"bag{i}" for i in range(n_bags)], ratio, 0.1)
    return ds, bag == n_bags - 1


def log_as_drive(th: np.ndarray, w: np.ndarray, tau: np.ndarray, fs: float, sub: int, rng) -> dict:
    """A motor simulated at ``sub`` fine steps per logging period (angle ``th``, speed ``w``, torque ``tau``) logged
    at ``fs`` as a drive logs it: angle and speed sampled at the period's start (speed noise 0.005 rad/s), the torque
    as its mean over the period (noise 0.02 N*m), the acceleration as the 20 ms Savitzky-Golay derivative of the
    logged speed. One bag's columns (theta_m, omega_m, alpha_m, tau_m); ``rng`` draws the speed noise first."""
    n = len(w) // sub
    t = np.arange(n) / fs
    w_log = w[::sub] + rng.normal(0, 0.005, n)
    return {"theta_m": th[::sub], "omega_m": w_log, "alpha_m": sg2_derivative(w_log, t, np.zeros(n, int), 0.02),
            "tau_m": tau.reshape(n, sub).mean(1) + rng.normal(0, 0.02, n)}


def log_motor_with_load(th, w, i_q, Q, rng, *, kt: float, ratio: float, fs: float, sub: int) -> dict:
    """A loaded motor's bag as a drive logs it: ``log_as_drive`` of the drive's torque k_t i_q (its nominal k_t), the
    output torque ``Q`` sampled with 0.05 N*m noise, Q / ratio, and i_q = tau_m / k_t (the current the drive logs)."""
    c = log_as_drive(th, w, kt * i_q, fs, sub, rng)
    n = len(c["tau_m"])
    c["Q_red"] = Q[::sub][:n] + rng.normal(0, 0.05, n)
    c["Q_red_over_N"] = c["Q_red"] / ratio
    c["i_q"] = c["tau_m"] / kt
    return c


def torsion_plant(spring, position_error=None, seed: int = 1, torque=None, stiffness=None
                  ) -> tuple[Dataset, np.ndarray]:
    """``spring(x)``: the torsion law's torque at deflection x; ``position_error(theta_m)``: e inside the spring;
    ``torque(theta_m, w)``: a torque added outside the spring (a ripple that does not pass through the torsion law);
    ``stiffness(theta_m)``: the spring's relative stiffness (it scales the whole law: 1 + eps cos(k theta_m) for a
    mesh whose teeth in contact vary with position)."""
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    t = np.arange(n) / FS
    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "theta_f", "phi", "windup", "windup_dot", "Q_red")}
    for i in range(N_BAGS):
        th = 40.0 * np.sin(2 * np.pi * (0.2 + 0.03 * i) * t)
        om = np.gradient(th, t)
        wu = 2.5e-3 * np.sin(2 * np.pi * (0.13 + 0.02 * i) * t + i) + 3e-4 * np.sin(2 * np.pi * 1.7 * t)
        wud = np.gradient(wu, t)
        x = wu if position_error is None else wu - position_error(th)
        Q = (spring(x) * (1.0 if stiffness is None else stiffness(th)) + 50.0 * wud + rng.normal(0, 3.0, n)
             + (0.0 if torque is None else torque(th, wu)))
        for k, v in (("theta_m", th), ("omega_m", om), ("alpha_m", np.gradient(om, t)), ("theta_f", th / N - wu),
                     ("phi", -wu), ("windup", wu), ("windup_dot", wud), ("Q_red", Q)):
            cols[k].append(v)
    return dataset(cols, t)


def stribeck_design(w: np.ndarray):
    """Columns [tanh(w / eps), exp(-(|w| / omega_s)^delta) tanh(w / eps), w] (T_C, dT, viscous b) as a function of the
    shapes ``omega_s``, ``delta``, ``eps``: a design for ``hd_twin.identify.fit_separable`` / ``vp_shape``."""
    def design(sh):
        sg = np.tanh(w / sh["eps"])
        return np.column_stack([sg, np.exp(-(np.abs(w) / sh["omega_s"]) ** sh["delta"]) * sg, w])
    return design
