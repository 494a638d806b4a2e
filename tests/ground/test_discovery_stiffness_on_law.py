"""Discovery (issue 10, thirty-sixth pass): a stiffness that varies with position scales the whole torsion law.

Synthetic twist-side plant (``synthetic.torsion_plant``, numpy only, no hd_sim): a lost motion of half-width J with a
hardening law beyond it, f(x) = K dz(x; J) + K3 dz(x; J)^3, whose stiffness varies with the wave generator's position,
Q_red = f(w) (1 + EPS cos(2 theta_m + PSI)). The candidate ripple of a linear spring, K eps w cos(2 theta_m), is
wrong inside the gap (no torque there to modulate) and beyond it (the ripple grows with the cubic part): discover
must read the ripple on its own identified law (``lawmod.refine_stiffness_modulation``), with eps the relative
modulation, and predict the held-out bag better than the linear ripple. A ripple that is linear in the twist (a
torque added outside the law) keeps the linear reading.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import Options, discover_signal

from .synthetic import torsion_plant

K, K3, J, EPS, PSI = 1.0e6, 2.0e11, 3.0e-4, 0.10, 0.4


def _law(x):
    dz = np.sign(x) * np.maximum(np.abs(x) - J, 0.0)
    return K * dz + K3 * dz**3


def _ripple(r):
    return [e for e in r.effects if e["name"] == "position_dependent_stiffness" and e["order"] == 2]


def test_a_stiffness_ripple_on_a_gap_and_a_hardening_law_is_read_on_that_law():
    ds, ho = torsion_plant(_law, stiffness=lambda th: 1.0 + EPS * np.cos(2 * th + PSI))
    r = discover_signal(ds, "Q_red", ho)
    rip = _ripple(r)
    assert rip, (r.effects, r.cv_trace)
    p = rip[0]["parameters"]
    assert p.get("law_modulated") == 1.0, [s for s in r.statements if "torsion law" in s]
    assert p["eps_2"] == pytest.approx(EPS, rel=0.05), p
    assert p["phase_2"] == pytest.approx(PSI + np.pi / 2, abs=0.05), p  # eps sin(2 theta_m + psi) = cos(. + PSI)
    assert any(e["name"] == "backlash" for e in r.effects), r.effects
    # the same data read with the linear ripple only (the option off): the law's reading predicts the held-out bag better
    lin = discover_signal(ds, "Q_red", ho, opt=Options(stiffness_law_modulation=False))
    assert r.error_after["rmse"] < 0.9 * lin.error_after["rmse"], (r.error_after, lin.error_after)


def test_a_ripple_linear_in_the_twist_keeps_the_linear_reading():
    ds, ho = torsion_plant(_law, torque=lambda th, w: K * EPS * w * np.cos(2 * th + PSI))
    r = discover_signal(ds, "Q_red", ho)
    rip = _ripple(r)
    assert rip, (r.effects, r.cv_trace)
    assert "law_modulated" not in rip[0]["parameters"], rip[0]["parameters"]
    assert any("the linear ripple is kept" in s for s in r.statements), [s for s in r.statements if "law" in s]
