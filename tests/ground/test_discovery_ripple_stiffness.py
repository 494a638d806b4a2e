"""Discovery (issue 10, tenth pass): a position ripple inside a hardening torsion law.

A kinematic error e(theta_m) inside the spring gives Q_red = f(w - e) ~ f(w) - f'(w) e; with a cubic law
f = K w + k3 w^3 that is the plain ripple K e plus 3 k3 w^2 e. The catalog's ``theta_m:k:stiff`` group
(w^2 sin/cos(k theta_m)) must join the plain ripple when the law is curved, and stay out when it is linear.
Synthetic plant: `synthetic.torsion_plant` (numpy only, no hd_sim).
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal

from .synthetic import torsion_plant

K, E2, PSI = 5.0e5, 4.0e-5, 0.7


def _plant(k3: float, seed: int = 2):
    return torsion_plant(lambda x: K * x + k3 * x**3, lambda th: E2 * np.sin(2 * th + PSI), seed)


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
