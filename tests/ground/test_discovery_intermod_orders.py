"""Discovery (issue 10, sixteenth pass): the orders a ripple takes on through a curved torsion law.

A position error e(theta_m) = E1 sin(theta_m + a) + E2 sin(2 theta_m + b) inside a hardening spring,
Q_red = f(w - e), f(x) = K x + k3 x^3, holds 3 k3 w e^2, whose cross term is a stiffness ripple at order 1 + 2 = 3:
-3 k3 E1 E2 w cos(3 theta_m + a + b). Its sign follows the load's, so the plain order spectrum averages it away
and it is not among the catalog's orders (1, 2, 4): before this pass it was never a candidate. The sums and
differences of the tried orders are candidates now, and selection (CV, fold majority, Wald) decides.
Synthetic plant: `synthetic.torsion_plant` (numpy only, no hd_sim); about 15 s.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal

from .synthetic import torsion_plant

K, K3, E1, E2 = 5.0e5, 1.0e11, 2.0e-4, 2.0e-4


def _plant(seed: int = 2):
    return torsion_plant(lambda x: K * x + K3 * x**3, lambda th: E1 * np.sin(th + 0.3) + E2 * np.sin(2 * th + 0.7), seed)


def test_the_intermodulation_order_of_two_ripples_through_a_cubic_law_is_found():
    ds, ho = _plant()
    r = discover_signal(ds, "Q_red", ho)
    o3 = [e for e in r.effects if e["variable"] == "theta_m" and e["order"] == 3]
    assert o3, r.cv_trace
    # the stiffness-ripple reading, with the amplitude the law gives it: 3 k3 E1 E2 (N*m/rad)
    amp = [e["parameters"]["K_eps_3"] for e in o3 if "K_eps_3" in e["parameters"]]
    assert amp and amp[0] == pytest.approx(3 * K3 * E1 * E2, rel=0.15), o3
    assert any("sums and differences" in s for s in r.statements), r.statements
