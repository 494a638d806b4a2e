"""The ``lowpass`` basis op: 1 / (1 + (k v / c)^2), the share of a disturbance at the frequency k |v| that a
band-limited loop shows (discovery's band-limited motor-angle ripple, issue 10's thirty-eighth pass), in numpy and
torch alike, carried by a term as any other op, and refused by name when its corner is not a positive number."""

import numpy as np
import pytest

from hd_twin.terms import evaluate_basis, evaluate_term, make_term, required_signals, validate_basis


def test_lowpass_share_is_one_at_rest_half_at_the_corner_and_even_in_speed():
    w = np.array([0.0, 2.0, -2.0, 20.0, 1e6])
    v = evaluate_basis({"op": "lowpass", "var": "omega_m", "k": 60.0, "corner": 120.0}, {"omega_m": w})
    np.testing.assert_allclose(v, 1.0 / (1.0 + (60.0 * w / 120.0) ** 2), rtol=1e-15)
    assert v[0] == 1.0 and v[1] == pytest.approx(0.5) and v[2] == v[1] and v[-1] < 1e-6


def test_lowpass_in_torch_and_in_a_ripple_term():
    torch = pytest.importorskip("torch")
    w = np.linspace(-30.0, 30.0, 61)
    th = np.linspace(0.0, 3.0, 61)
    lp = {"op": "lowpass", "var": "omega_m", "k": 60.0, "corner": 300.0}
    basis = [{"op": "prod", "factors": [{"op": "sin", "var": "theta_m", "k": 60.0}, lp]},
             {"op": "prod", "factors": [{"op": "cos", "var": "theta_m", "k": 60.0}, lp]}]
    term = make_term("cogging_torque", "tau_m", basis, [0.03, -0.01], variable="theta_m", order=60.0)
    share = 1.0 / (1.0 + (60.0 * w / 300.0) ** 2)
    expect = (0.03 * np.sin(60.0 * th) - 0.01 * np.cos(60.0 * th)) * share
    np.testing.assert_allclose(evaluate_term(term, {"omega_m": w, "theta_m": th}), expect, rtol=1e-12, atol=1e-15)
    t = evaluate_term(term, {"omega_m": torch.tensor(w), "theta_m": torch.tensor(th)}, xp=torch)
    np.testing.assert_allclose(t.numpy(), expect, rtol=1e-12, atol=1e-15)
    assert required_signals([term]) == {"omega_m", "theta_m"}


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan"), float("inf"), "wide", None])
def test_lowpass_needs_a_positive_finite_corner(bad):
    with pytest.raises(ValueError, match="corner"):
        validate_basis({"op": "lowpass", "var": "omega_m", "k": 6.0, "corner": bad})


def test_lowpass_needs_its_order():
    with pytest.raises(ValueError, match="'k' of lowpass"):
        validate_basis({"op": "lowpass", "var": "omega_m", "corner": 10.0})
