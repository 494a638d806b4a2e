"""Discovery (issue 10, twenty-seventh pass): a kinematic error through a lost motion.

A position error e(theta_m) acts inside the spring, Q_red = f(w - e) ~ f(w) - f'(w) e. With lost motion of half-width
j the spring transmits nothing inside |w| < j (f' = 0, no teeth in contact), so the error's torque ripple vanishes
there. The catalog's ``theta_m:k:contact`` group, the ripple inside |w| < j with its own width identified by the CV
profile, must join the plain ripple there (coefficient -A, width the dead zone's), and stay out where the ripple does
not pass through the lost motion (a torque added outside the spring) or where there is no lost motion (linear law).
Synthetic plant: `synthetic.torsion_plant` (numpy only, no hd_sim).
"""

import numpy as np
import pytest

from hd_ground.discovery.core import _premise_holds, discover_signal
from hd_twin.terms import evaluate_basis, validate_basis

from .synthetic import torsion_plant

K, J, E2, PSI = 1.0e6, 1.5e-4, 4.0e-5, 0.4


def _dead_zone(x):
    return K * np.sign(x) * np.maximum(np.abs(x) - J, 0)


def _ke(r):
    ke = [e for e in r.effects if e["name"] == "kinematic_error_harmonic"]
    return ([e for e in ke if "A_2" in e["parameters"]], [e for e in ke if "K_c_2" in e["parameters"]])


@pytest.mark.parametrize("seed", [1, 2])
def test_a_ripple_through_the_lost_motion_vanishes_inside_it(seed):
    ds, ho = torsion_plant(_dead_zone, lambda th: E2 * np.sin(2 * th + PSI), seed)
    r = discover_signal(ds, "Q_red", ho)
    plain, contact = _ke(r)
    assert plain and contact, r.cv_trace
    A, c = plain[0]["parameters"], contact[0]["parameters"]
    assert A["A_2"] == pytest.approx(K * E2, rel=0.05)
    # inside the lost motion the ripple is gone: the contact part cancels the plain ripple (opposite phase, same size)
    assert c["K_c_2"] == pytest.approx(A["A_2"], rel=0.15)
    assert abs(np.angle(np.exp(1j * (c["phase_2"] - A["phase_2"] - np.pi)))) < 0.1
    assert c["j"] == pytest.approx(J, rel=0.1)  # its own width, identified: the dead zone's
    assert r.error_after["rmse"] < 1.2 * 3.0  # the plant's noise SD


def test_a_ripple_outside_the_spring_does_not_get_the_contact_part():
    # the same dead zone, the same ripple's size, added as a torque that does not pass through the torsion law
    ds, ho = torsion_plant(_dead_zone, None, 1, torque=lambda th, w: -K * E2 * np.sin(2 * th + PSI))
    r = discover_signal(ds, "Q_red", ho)
    plain, contact = _ke(r)
    assert plain and not contact, r.cv_trace
    assert any(e["name"] == "backlash" for e in r.effects)


def test_no_lost_motion_no_contact_part():
    ds, ho = torsion_plant(lambda x: K * x, lambda th: E2 * np.sin(2 * th + PSI), 1)
    r = discover_signal(ds, "Q_red", ho)
    plain, contact = _ke(r)
    assert plain and not contact, r.cv_trace
    assert not any("contact" in t.get("candidate", "") for t in r.cv_trace)  # its premise never held


def test_within_op_and_the_premise_rule():
    x = np.array([-3.0, -1.0, 0.0, 1.0, 2.0, 3.0])
    spec = {"op": "within", "var": "w", "width": 2.0}
    assert evaluate_basis(spec, {"w": x}).tolist() == [0.0, 1.0, 1.0, 1.0, 0.5, 0.0]
    torch = pytest.importorskip("torch")
    assert evaluate_basis(spec, {"w": torch.tensor(x)}, xp=torch).tolist() == [0.0, 1.0, 1.0, 1.0, 0.5, 0.0]
    with pytest.raises(ValueError, match="width"):
        validate_basis({"op": "within", "var": "w", "width": -1.0})

    class Gram:  # coefficients of the current model's columns
        def coef(self, idx):
            return np.array([{0: 1.0, 3: -2.0, 4: 5.0}[i] for i in idx])

    class C:
        def __init__(self, fam):
            self.family = fam
    groups = [(C("backlash"), [3, 4]), (C("theta_m:2"), [5])]
    assert _premise_holds(Gram(), [0, 3, 4], groups, [0], None)
    assert not _premise_holds(Gram(), [0, 3, 4], groups, [0], ("backlash", 0))  # K_j < 0: not a lost motion
    assert _premise_holds(Gram(), [0, 3, 4], groups, [0], ("backlash", 1))
    assert not _premise_holds(Gram(), [0], groups, [], ("backlash", 0))  # not selected
