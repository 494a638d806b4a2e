"""The ``deadzone`` basis op's optional soft edge (``edge``: softplus corners of width s), the form a lost motion
with a compliant first contact takes (hd_sim's dead zone is written so), for the next candidate issue 10's default
backlash rows ask for (README, session 18: `bench/diag_dead_zone_edge.py`)."""

import numpy as np
import pytest

from hd_twin.terms import evaluate_basis, validate_basis


def _soft(x, d, s):
    return s * (np.logaddexp(0.0, (x - d) / s) - np.logaddexp(0.0, (-x - d) / s))


def test_soft_edge_is_the_softplus_dead_zone_and_tends_to_the_hard_one():
    x = np.linspace(-3e-3, 3e-3, 2001)
    d, s = 1e-3, 1e-4
    soft = evaluate_basis({"op": "deadzone", "var": "w", "width": d, "edge": s}, {"w": x})
    np.testing.assert_allclose(soft, _soft(x, d, s), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(soft, -soft[::-1], atol=1e-18)  # odd
    hard = evaluate_basis({"op": "deadzone", "var": "w", "width": d}, {"w": x})
    assert np.max(np.abs(soft - hard)) <= s * np.log(2.0) * (1 + 1e-9)  # largest at the corners, s ln 2
    corner = evaluate_basis({"op": "deadzone", "var": "w", "width": d, "edge": s}, {"w": np.array([d])})
    assert corner[0] == pytest.approx(s * np.log(2.0), rel=1e-6)
    far = np.abs(x) > d + 20 * s
    np.testing.assert_allclose(soft[far], hard[far], atol=1e-12)
    narrow = evaluate_basis({"op": "deadzone", "var": "w", "width": d, "edge": 1e-9}, {"w": x})
    np.testing.assert_allclose(narrow, hard, atol=1e-9)
    # edge 0 is the hard dead zone
    zero = evaluate_basis({"op": "deadzone", "var": "w", "width": d, "edge": 0.0}, {"w": x})
    np.testing.assert_array_equal(zero, hard)
    # no overflow far from the corners (a tiny edge against a large twist)
    big = evaluate_basis({"op": "deadzone", "var": "w", "width": d, "edge": 1e-12}, {"w": np.array([-1.0, 1.0])})
    assert np.all(np.isfinite(big)) and big.tolist() == pytest.approx([-(1.0 - d), 1.0 - d])


def test_soft_edge_in_torch_and_bad_edges():
    torch = pytest.importorskip("torch")
    x = np.linspace(-3e-3, 3e-3, 101)
    spec = {"op": "deadzone", "var": "w", "width": 1e-3, "edge": 2e-4}
    t = evaluate_basis(spec, {"w": torch.tensor(x, dtype=torch.float64)}, xp=torch)
    np.testing.assert_allclose(t.numpy(), _soft(x, 1e-3, 2e-4), rtol=1e-12, atol=1e-18)
    for bad in (-1e-4, float("nan"), "wide"):
        with pytest.raises((ValueError, TypeError), match="edge"):
            validate_basis({"op": "deadzone", "var": "w", "width": 1e-3, "edge": bad})
