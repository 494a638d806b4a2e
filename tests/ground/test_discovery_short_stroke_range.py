"""The short-stroke stand-in's powers are known on the fit data's range only and continued linearly beyond it
(hd_twin.terms.pow_within, library.short_stroke_candidates).

Known answer: an output-angle torque 0.05 sin(3 theta_f + 0.9) N*m (plant2's output_periodic shape) seen over a fit
stroke of [-0.26, 0.43] rad (0.11 revolutions: its periodicity is not identifiable) and asked beyond it, down to
-0.44 rad, as seed 5500's held-out plant2 mission was. Inside the range the columns are the plain powers; beyond
it the cubic's u^3 runs away, its linear continuation stays near the torque.
"""

from __future__ import annotations

import numpy as np
import pytest

from hd_twin.terms import basis_matrix, evaluate_basis, pow_within, validate_basis


def test_pow_within_is_the_power_inside_and_linear_beyond():
    x = np.linspace(-1.0, 1.5, 501)
    lo, hi, c = -0.3, 0.7, 0.1
    for p in (1.0, 2.0, 3.0):
        v = pow_within(x, p, c, lo, hi)
        inside = (x >= lo) & (x <= hi)
        assert np.allclose(v[inside], (x[inside] - c) ** p)
        for b, side in ((lo, x < lo), (hi, x > hi)):
            assert np.allclose(v[side], (b - c) ** p + p * (b - c) ** (p - 1) * (x[side] - b))
        assert np.allclose(np.diff(v[x > hi], 2), 0.0, atol=1e-12) and np.allclose(np.diff(v[x < lo], 2), 0.0,
                                                                                  atol=1e-12)
    spec = {"op": "pow", "var": "theta_f", "p": 3.0, "ref": c, "lo": lo, "hi": hi}
    validate_basis(spec)
    assert np.allclose(evaluate_basis(spec, {"theta_f": x}), pow_within(x, 3.0, c, lo, hi))
    with pytest.raises(ValueError, match="lo < hi"):
        validate_basis(dict(spec, lo=hi, hi=lo))
    with pytest.raises(ValueError, match="'hi' of pow"):
        validate_basis({"op": "pow", "var": "theta_f", "p": 2.0, "lo": lo})
    torch = pytest.importorskip("torch")
    xt = torch.tensor(x, dtype=torch.float64, requires_grad=True)
    vt = evaluate_basis(spec, {"theta_f": xt}, xp=torch)
    assert np.allclose(vt.detach().numpy(), pow_within(x, 3.0, c, lo, hi))
    vt.sum().backward()  # differentiable (the PINN's physics residual carries terms)
    assert np.all(np.isfinite(xt.grad.numpy()))


def test_short_stroke_stand_in_continued_linearly_beyond_its_range():
    from hd_ground.discovery.library import LibraryContext, build_candidates

    lo, hi = -0.26, 0.43
    ctx = LibraryContext(target="tau_m", available={"omega_m", "theta_f", "tau_m"}, omega_scale=10.0, omega_low=1.0,
                         sgn_eps=0.05, t_ref=25.0, excluded={"theta_f", "temperature", "load"},
                         short_stroke={"theta_f": (0.5 * (lo + hi), 0.5 * (hi - lo), lo, hi)})
    cand = next(c for c in build_candidates(ctx) if c.family == "theta_f:smooth" and c.level_carrier == {"op": "const"})
    truth = lambda th: 0.05 * np.sin(3 * th + 0.9)  # noqa: E731
    rng = np.random.default_rng(0)
    th_fit = rng.uniform(lo, hi, 4000)
    y = truth(th_fit) + 0.002 * rng.normal(size=th_fit.size)
    X = basis_matrix(cand.basis, {"theta_f": th_fit})
    cubic = np.column_stack([(th_fit - ctx.short_stroke["theta_f"][0]) ** k for k in range(4)])
    assert np.allclose(X, cubic)  # on the fit rows: the plain powers (selection and CV unchanged)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    th_ho = np.linspace(-0.44, 0.37, 801)
    beyond = th_ho < lo
    err_lin = basis_matrix(cand.basis, {"theta_f": th_ho}) @ coef - truth(th_ho)
    err_cub = np.column_stack([(th_ho - ctx.short_stroke["theta_f"][0]) ** k for k in range(4)]) @ coef - truth(th_ho)
    assert np.allclose(err_lin[~beyond], err_cub[~beyond])
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(err_lin[beyond]) < 0.7 * rms(err_cub[beyond]), (rms(err_lin[beyond]), rms(err_cub[beyond]))
    term = cand.term("tau_m", coef)
    assert term["parameters"]["range_lo"] == lo and term["parameters"]["range_hi"] == hi
    assert "continued linearly beyond" in term["form"]
