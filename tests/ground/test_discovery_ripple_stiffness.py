"""Discovery (issue 10, tenth pass): a position ripple inside a hardening torsion law.

A kinematic error e(theta_m) inside the spring gives Q_red = f(w - e) ~ f(w) - f'(w) e; with a cubic law
f = K w + k3 w^3 that is the plain ripple K e plus 3 k3 w^2 e. The catalog's ``theta_m:k:stiff`` group
(w^2 sin/cos(k theta_m)) must join the plain ripple when the law is curved, and stay out when it is linear.
Synthetic plant written here (numpy only, no hd_sim).
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal
from hd_ground.discovery.data import Dataset

FS, T_BAG, N_BAGS, N = 500.0, 8.0, 4, 80.0
K, E2, PSI = 5.0e5, 4.0e-5, 0.7


def _plant(k3: float, seed: int = 2):
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    t = np.arange(n) / FS
    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "theta_f", "phi", "windup", "windup_dot", "Q_red")}
    for i in range(N_BAGS):
        th = 40.0 * np.sin(2 * np.pi * (0.2 + 0.03 * i) * t)
        om = np.gradient(th, t)
        wu = 2.5e-3 * np.sin(2 * np.pi * (0.13 + 0.02 * i) * t + i) + 3e-4 * np.sin(2 * np.pi * 1.7 * t)
        wud = np.gradient(wu, t)
        x = wu - E2 * np.sin(2 * th + PSI)  # the spring's own deflection
        Q = K * x + k3 * x**3 + 50.0 * wud + rng.normal(0, 3.0, n)
        for k, v in (("theta_m", th), ("omega_m", om), ("alpha_m", np.gradient(om, t)), ("theta_f", th / N - wu),
                     ("phi", -wu), ("windup", wu), ("windup_dot", wud), ("Q_red", Q)):
            cols[k].append(v)
    sig = {k: np.concatenate(v) for k, v in cols.items()}
    bag = np.repeat(np.arange(N_BAGS), n)
    frac = np.tile(t / t[-1], N_BAGS)
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    ds = Dataset(sig, bag, block, frac, np.tile(t, N_BAGS), bag.copy(), [f"bag{i}" for i in range(N_BAGS)], N, 0.1)
    return ds, bag == N_BAGS - 1


@pytest.mark.parametrize("k3", [0.0, 1.0e11])
def test_ripple_through_the_local_stiffness_joins_only_a_curved_law(k3):
    ds, ho = _plant(k3)
    r = discover_signal(ds, "Q_red", ho)
    ke = [e for e in r.effects if e["name"] == "kinematic_error_harmonic"]
    plain = [e for e in ke if "A_2" in e["parameters"]]
    stiff = [e for e in ke if "K_b_2" in e["parameters"]]
    assert plain and plain[0]["parameters"]["A_2"] == pytest.approx(K * E2, rel=0.1), r.cv_trace
    if k3 == 0.0:
        assert not stiff, r.cv_trace
    else:
        assert stiff, r.cv_trace
        assert stiff[0]["parameters"]["K_b_2"] == pytest.approx(3 * k3 * E2, rel=0.2), r.effects
