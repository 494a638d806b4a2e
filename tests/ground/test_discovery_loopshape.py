"""The hysteresis loop's shape identified from data (hd_ground.discovery.loopshape, hd_twin.identify.hysteresis_state).

A twist-side loop K w + T_h s(w) with a known Bouc-Wen shape: the shape (n, phi) must be identified by variable
projection on the cross-validated residuals (within its sandwich SEs of the truth) and replace the Dahl loop the
selection starts from; a Dahl loop must be recovered as Dahl (n = 1, phi = 1) and kept.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import StateSignals
from hd_ground.discovery.library import Candidate, state_var
from hd_ground.discovery.loopshape import refine_loop_shape
from hd_twin.identify import Shape, hysteresis_state, presliding_state
from hd_twin.terms import basis_matrix


def _euler(x, d, n, phi, m=400):
    """Reference: the Bouc-Wen ODE integrated with m Euler sub-steps per sample."""
    z, out = 0.0, np.zeros(len(x))
    for i in range(1, len(x)):
        h = (x[i] - x[i - 1]) / m
        for _ in range(m):
            a = abs(z) ** n
            z += h / d * ((1.0 - a) if z * h >= 0 else (1.0 + phi * a))
        out[i] = z
    return out


def test_state_is_dahl_at_n1_phi1_and_matches_the_ode_elsewhere():
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 10.0, 4000)
    x = 1e-3 * np.sin(2 * np.pi * 0.3 * t) + 3e-4 * np.sin(2 * np.pi * 1.7 * t) + 2e-5 * rng.standard_normal(t.size)
    seg = (t > 6).astype(int)
    assert np.max(np.abs(hysteresis_state(x, 2e-4, 1.0, 1.0, seg) - presliding_state(x, 2e-4, seg))) < 1e-5
    s = hysteresis_state(x, 2e-4, 1.0, 1.0, seg)
    assert s[np.flatnonzero(seg)[0]] == 0.0  # a new segment restarts the state
    xs = x[:600]
    for n, phi in ((2.0, 0.0), (0.7, 2.0)):
        assert np.max(np.abs(hysteresis_state(xs, 2e-4, n, phi) - _euler(xs, 2e-4, n, phi))) < 2e-3
    with pytest.raises(ValueError):
        hysteresis_state(xs, 2e-4, 1.0, -1.5)


def _loop_case(n, phi, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 24.0, 2e-3)
    # a load cycling at two amplitudes (major and minor loops), three missions (segments)
    w = (8e-4 * np.sin(2 * np.pi * 0.35 * t) * (1 + 0.5 * np.sin(2 * np.pi * 0.05 * t))
         + 2.5e-4 * np.sin(2 * np.pi * 1.9 * t))
    seg = (t // 8).astype(int)
    K, T_h, d = 1.0e6, 120.0, 2e-4
    Q = K * w + T_h * hysteresis_state(w, d, n, phi, seg) + 4.0 * rng.standard_normal(t.size)
    block = (t // 0.8).astype(int)
    sig = StateSignals({"windup": w}, ({"windup": w}, seg, {}), np.arange(t.size))
    rows = np.arange(0, t.size, 2)
    s_rows = sig.rows_of(rows)

    def dahl_basis(sh):
        return [{"op": "var", "var": state_var("windup", sh["d_h"])}]

    cand = Candidate("hysteresis", "hysteresis", "windup", None, dahl_basis({"d_h": 3e-4}), "T_h s",
                     lambda c: {"T_h": float(c[0])}, positive=True, nonlinear={"d_h": 3e-4},
                     shapes=[Shape("d_h", 1e-5, 2e-3, log=True, n_grid=12)], nuisance=("d_h",), make_basis=dahl_basis)
    Xc = np.c_[w[rows]]

    def design_of(make_basis):
        return lambda sh: np.column_stack([Xc, basis_matrix(make_basis(sh), s_rows)])

    changed, notes = refine_loop_shape(cand, design_of, Q[rows], block[rows], min_gain=0.02)
    return changed, notes, cand


def test_a_bouc_wen_loop_with_linear_unloading_is_identified_and_replaces_dahl():
    changed, notes, cand = _loop_case(n=2.0, phi=0.0, seed=3)
    p = cand.nonlinear
    assert changed, notes
    assert not p["n_h_weak"] and not p["phi_h_weak"]
    for k, truth in (("n_h", 2.0), ("phi_h", 0.0)):
        assert abs(p[k] - truth) < max(3 * p[f"{k}_se"], 0.05), (k, p[k], p[f"{k}_se"])
        assert p[f"{k}_se"] < 0.5
    assert abs(p["d_h"] / 2e-4 - 1.0) < 0.2
    # the group now rides on the identified loop, d_h still searched by the selection
    assert cand.basis[0]["var"].count(":") == 4 and [s.name for s in cand.shapes] == ["d_h"]
    assert "replaces the Dahl loop" in notes[0]


def test_a_dahl_loop_is_recovered_as_dahl_and_kept():
    changed, notes, cand = _loop_case(n=1.0, phi=1.0, seed=4)
    p = cand.nonlinear
    assert not changed, notes
    assert "Dahl loop is kept" in notes[0]
    for k, truth in (("n_h", 1.0), ("phi_h", 1.0)):
        # measured: n 0.988 +- 0.006, phi 0.947 +- 0.014 (the sandwich is optimistic at this signal-to-noise)
        assert abs(p[k] - truth) < 0.1, (k, p[k], p[f"{k}_se"])
    assert p["n_h_se"] < 0.5
    assert cand.basis[0]["var"] == state_var("windup", cand.nonlinear["d_h"])  # unchanged
