"""The shared additive-term format (src/hd_twin/terms.py): numpy/torch agreement, validation, JSON."""

import json

import numpy as np
import pytest

from hd_twin.terms import (
    evaluate_terms,
    harmonic_amplitude_phase,
    make_term,
    required_signals,
    sin_cos_pair,
    terms_from_json,
    terms_to_json,
)


def _signals(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return {
        "theta_m": np.cumsum(rng.uniform(0, 0.05, n)),
        "omega_m": rng.normal(0, 5, n),
        "temperature": 20 + rng.normal(0, 3, n),
        "Q_red": rng.normal(0, 10, n),
    }


def _terms():
    sgn = {"op": "sgn", "var": "omega_m"}
    return [
        make_term("position_periodic_friction", "tau_m", sin_cos_pair("theta_m", 2, sgn), [0.03, -0.01],
                  variable="theta_m", order=2),
        make_term("stribeck_friction", "tau_m", [{"op": "stribeck", "var": "omega_m", "v_s": 2.0, "delta": 1.5}],
                  [0.05], variable="omega_m"),
        make_term("temperature_dependent_friction", "tau_m",
                  [{"op": "prod", "factors": [{"op": "var", "var": "omega_m"},
                                               {"op": "offset", "var": "temperature", "ref": 25.0}]}],
                  [-1e-6], variable="temperature"),
        make_term("load_dependent_friction", "Q_red",
                  [{"op": "prod", "factors": [{"op": "abs", "var": "Q_red"}, sgn]}], [0.002], variable="Q_red"),
    ]


def test_numpy_values_match_hand_formulas():
    s = _signals()
    t = _terms()
    sg = np.sign(s["omega_m"])
    want_tau = (0.03 * np.sin(2 * s["theta_m"]) - 0.01 * np.cos(2 * s["theta_m"])) * sg \
        + 0.05 * np.exp(-(np.abs(s["omega_m"]) / 2.0) ** 1.5) * sg \
        - 1e-6 * s["omega_m"] * (s["temperature"] - 25.0)
    np.testing.assert_allclose(evaluate_terms(t, s, signal="tau_m"), want_tau, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(evaluate_terms(t, s, signal="Q_red"), 0.002 * np.abs(s["Q_red"]) * sg, rtol=1e-12)
    assert np.all(evaluate_terms([], s) == 0) and evaluate_terms([], s).shape == s["omega_m"].shape
    assert required_signals(t) == {"theta_m", "omega_m", "temperature", "Q_red"}


def test_torch_matches_numpy_and_is_differentiable():
    torch = pytest.importorskip("torch")
    s = _signals()
    t = _terms()
    st = {k: torch.tensor(v, dtype=torch.float64, requires_grad=(k == "theta_m")) for k, v in s.items()}
    yt = evaluate_terms(t, st, xp=torch)
    np.testing.assert_allclose(yt.detach().numpy(), evaluate_terms(t, s), rtol=1e-10, atol=1e-14)
    yt.sum().backward()
    assert st["theta_m"].grad is not None and torch.isfinite(st["theta_m"].grad).all()


def test_json_round_trip_and_harmonic_parameters():
    t = _terms()
    back = terms_from_json(terms_to_json(t))
    assert back == json.loads(json.dumps(t))
    a, psi = harmonic_amplitude_phase(0.03, -0.01)
    x = np.linspace(0, 7, 50)
    np.testing.assert_allclose(0.03 * np.sin(x) - 0.01 * np.cos(x), a * np.sin(x + psi), atol=1e-12)


@pytest.mark.parametrize(
    "bad, msg",
    [
        ({"name": "x", "signal": "speed", "basis": [{"op": "const"}], "coef": [1]}, "signal"),
        ({"name": "x", "signal": "tau_m", "basis": [{"op": "wobble", "var": "a"}], "coef": [1]}, "unknown basis op"),
        ({"name": "x", "signal": "tau_m", "basis": [{"op": "const"}], "coef": [1, 2]}, "coef"),
        ({"name": "x", "signal": "tau_m", "basis": [{"op": "const"}], "coef": [float("nan")]}, "finite"),
        ({"name": "x", "signal": "tau_m", "basis": [{"op": "stribeck", "var": "omega_m", "v_s": -1}], "coef": [1]}, "v_s"),
    ],
)
def test_bad_terms_are_refused_with_a_clear_message(bad, msg):
    with pytest.raises(ValueError, match=msg):
        evaluate_terms([bad], _signals())


@pytest.mark.parametrize(
    "basis, signals, msg",
    [
        # a hostile Reynolds rate: exp(1e4 (T - 20)) overflows on every warm sample
        ({"op": "expm1", "var": "temperature", "k": 1e4, "ref": 20.0}, None, "expm1 with k=10000"),
        # a fractional power of a signed speed: NaN on every reverse sample
        ({"op": "pow", "var": "omega_m", "p": 0.5}, None, "pow with p=0.5"),
        # a negative power at standstill: inf
        ({"op": "pow", "var": "omega_m", "p": -1.0}, {"omega_m": np.array([1.0, 0.0, 2.0])}, "1 of 3 samples"),
    ],
)
def test_a_term_that_leaves_the_reals_on_finite_signals_is_refused_by_name(basis, signals, msg):
    """A model file whose parameters pass validation but overflow on the data (expm1 with a huge rate, a
    fractional or negative power where the signal is negative or zero) is an error naming the term and the op,
    in numpy and in torch, never an inf/NaN prediction passed on to residuals, flags or a training loss."""
    s = signals or _signals()
    t = [{"name": "reynolds_viscosity", "signal": "tau_m", "basis": [basis], "coef": [1.0]}]
    with pytest.raises(ValueError, match=msg) as e:
        evaluate_terms(t, s)
    assert "reynolds_viscosity" in str(e.value)
    torch = pytest.importorskip("torch")
    with pytest.raises(ValueError, match=msg):
        evaluate_terms(t, {k: torch.tensor(v) for k, v in s.items()}, xp=torch)


def test_a_dropout_in_the_input_stays_the_callers_and_a_sane_term_is_unchanged():
    """Only finite inputs are checked: a NaN sample (a dropout) passes through as NaN; a rate that fits the
    signal's range evaluates as the formula."""
    t = [make_term("reynolds_viscosity", "tau_m", [{"op": "expm1", "var": "temperature", "k": -0.03, "ref": 20.0}],
                   [0.5])]
    T = np.array([20.0, np.nan, 50.0])
    out = evaluate_terms(t, {"temperature": T})
    assert np.isnan(out[1])
    np.testing.assert_allclose(out[[0, 2]], 0.5 * np.expm1(-0.03 * (T[[0, 2]] - 20.0)), rtol=1e-12)


def test_missing_signal_names_term_and_signal():
    t = [make_term("cogging_torque", "tau_m", sin_cos_pair("theta_e", 6), [1, 0])]
    with pytest.raises(KeyError, match="theta_e"):
        evaluate_terms(t, _signals())


def test_jackknife_wald_separates_an_identified_term_from_one_that_changes_from_block_to_block():
    """A regressor with one coefficient in every block is identified; one whose coefficient flips sign
    from block to block (it soaks up something different in each) is not, though it lowers the fit error."""
    import numpy as np

    from hd_ground.discovery.core import _BlockGram, _wald_threshold

    rng = np.random.default_rng(3)
    n, nb = 4000, 10
    block = np.repeat(np.arange(nb), n // nb)
    x0 = np.ones(n)
    x1 = rng.normal(size=n)
    x2 = rng.normal(size=n)
    flip = np.where(block % 2 == 0, 1.0, -1.0) * rng.uniform(0.5, 1.5, nb)[block]
    y = 0.3 * x0 + 1.0 * x1 + 0.4 * flip * x2 + 0.1 * rng.normal(size=n)
    gram = _BlockGram(np.stack([x0, x1, x2], 1), y, block)
    thr = _wald_threshold(1, 3.0)
    assert abs(thr - 9.0) < 1e-6
    assert gram.jackknife_wald([0, 1, 2], [1]) > 100 * thr
    assert gram.jackknife_wald([0, 1, 2], [2]) < thr
