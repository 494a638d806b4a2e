"""The ``sum`` basis op: a fixed function made of other specs, sum_i w_i spec_i (discovery's stiffness ripple on an
identified torsion law puts the law inside a product, ``hd_ground.discovery.lawmod``); numpy and torch alike, and
malformed sums rejected naming the problem."""

import numpy as np
import pytest

from hd_twin.terms import basis_matrix, children, evaluate_basis, required_signals, validate_basis, with_children

LAW = {"op": "sum", "terms": [{"op": "var", "var": "w"}, {"op": "deadzone", "var": "w", "width": 1e-3},
                              {"op": "pow", "var": "w", "p": 3.0}], "weights": [2.0, -1.5, 4e6]}


def _law(x):
    return 2.0 * x - 1.5 * np.sign(x) * np.maximum(np.abs(x) - 1e-3, 0.0) + 4e6 * x**3


def test_sum_is_the_weighted_sum_of_its_terms_also_inside_a_product():
    x, th = np.linspace(-3e-3, 3e-3, 501), np.linspace(0, 7, 501)
    sig = {"w": x, "theta_m": th}
    validate_basis(LAW)
    np.testing.assert_allclose(evaluate_basis(LAW, sig), _law(x), rtol=1e-12, atol=1e-18)
    prod = {"op": "prod", "factors": [{"op": "sin", "var": "theta_m", "k": 2.0}, LAW]}
    np.testing.assert_allclose(basis_matrix([prod], sig)[:, 0], np.sin(2 * th) * _law(x), rtol=1e-12, atol=1e-18)
    assert required_signals([{"basis": [prod]}]) == {"w", "theta_m"}
    assert children(LAW) == LAW["terms"] and children({"op": "var", "var": "w"}) == []
    assert with_children(LAW, [{"op": "const"}] * 3)["terms"] == [{"op": "const"}] * 3


def test_sum_in_torch():
    torch = pytest.importorskip("torch")
    x = np.linspace(-3e-3, 3e-3, 101)
    t = evaluate_basis(LAW, {"w": torch.tensor(x, dtype=torch.float64)}, xp=torch)
    np.testing.assert_allclose(t.numpy(), _law(x), rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("bad, what", [
    ({"op": "sum", "terms": [], "weights": []}, "non-empty list 'terms'"),
    ({"op": "sum", "terms": [{"op": "var", "var": "w"}], "weights": [1.0, 2.0]}, "one number in 'weights'"),
    ({"op": "sum", "terms": [{"op": "var", "var": "w"}]}, "one number in 'weights'"),
    ({"op": "sum", "terms": [{"op": "var", "var": "w"}], "weights": [float("nan")]}, "weights\\[0\\]"),
    ({"op": "sum", "terms": [{"op": "bogus", "var": "w"}], "weights": [1.0]}, "terms\\[0\\]"),
])
def test_malformed_sums_are_rejected_naming_the_problem(bad, what):
    with pytest.raises(ValueError, match=what):
        validate_basis(bad, "law")


def test_nesting_beyond_the_limit_is_refused_by_name():
    from hd_twin.terms import MAX_BASIS_DEPTH

    spec = {"op": "var", "var": "w"}
    for i in range(MAX_BASIS_DEPTH):
        spec = {"op": "sum", "terms": [spec], "weights": [1.0]} if i % 2 else {"op": "prod", "factors": [spec]}
    validate_basis(spec)  # at the limit: fine
    for _ in range(5000):  # a hostile model file: far beyond Python's recursion limit
        spec = {"op": "prod", "factors": [spec]}
    with pytest.raises(ValueError, match="nested deeper than"):
        validate_basis(spec, "model.json")
