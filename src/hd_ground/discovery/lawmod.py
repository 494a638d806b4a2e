"""A stiffness that varies with position scales the whole torsion law (issue 10: position-dependent stiffness on a
plant whose torsion law is not linear).

The position-dependent stiffness candidate (``library.periodic_candidates``, variant "twist") is
``K eps_k w cos(k theta_m + psi_k)``: the ripple of a linear spring. The number of teeth in contact varies with the
wave generator's lobes, so the mesh stiffness is ``k_m (1 + eps cos(k theta_m + psi))``, and what it multiplies is
the torsion law itself, whatever its shape: ``Q = f(w) (1 + eps cos(k theta_m + psi))``. On a law with lost motion,
a hardening cubic or a knee, ``f(w) != K w``: inside a gap there is no torque to modulate, and a hardening law's
ripple grows with w^3. The linear reading then leaves a structured floor that other candidates (a w^2 ripple named
as a kinematic error) try to explain.

Once a linear stiffness ripple is selected beside a nonlinear torsion law (a selected group whose columns are
functions of the twist alone: a lost motion, a cubic term, a knot), this step reads the ripple on the identified
law: the group ``[f(w) sin(k theta_m), f(w) cos(k theta_m)]`` with ``f`` the model's own law (its baseline K w and
those groups, at their fitted coefficients), the pair (eps_k, psi_k) a relative modulation. ``f`` and the ripple
are identified together by alternating least squares (the bilinear model f(w)(1 + eps s(theta)); the law's
weights are the model's, refitted with the ripple in). The comparison is honest: both readings' errors are the
leave-one-block-out residuals, and for the modulated one the law's weights inside the ripple are refitted without
the held-out block as well.

The modulated ripple **replaces** the linear one only by the selection's own rules: the fit blocks' CV error lower
by ``min_gain``, in at least ``fold_majority`` of the blocks. The selection is then made again with it (once), so a
w^2 ripple that stood in for it can leave. Otherwise the linear ripple stays and the comparison is reported.
Nothing here assumes hd_sim's law: ``f`` is whatever the data selected.
"""

from __future__ import annotations

import numpy as np

from hd_twin.identify import scaled_lstsq
from hd_twin.terms import basis_matrix, children, harmonic_amplitude_phase

from .library import Candidate, _kstr

#: alternating least-squares rounds (the ripple is a few % of the law: the law's weights settle in two or three)
ALS_ROUNDS = 4


def is_linear_stiffness_ripple(cand: Candidate) -> bool:
    """A position-dependent stiffness group read on the linear spring: ``w sin / cos(k theta_m)``."""
    if cand.name != "position_dependent_stiffness" or cand.nonlinear.get("law_modulated") or len(cand.basis) != 2:
        return False
    for b in cand.basis:
        if b.get("op") != "prod":
            return False
        kinds = sorted(f.get("op") for f in b["factors"])
        if kinds not in (["sin", "var"], ["cos", "var"]) or not any(
                f.get("op") == "var" and f.get("var") == "windup" for f in b["factors"]):
            return False
    return True


def _twist_only(b: dict) -> bool:
    if children(b):
        return all(_twist_only(f) for f in children(b))
    return b.get("var") == "windup" and b.get("op") in ("var", "pow", "deadzone")


def is_torsion_law(cand: Candidate) -> bool:
    """A selected group that is part of the torsion law: every column a static function of the twist alone (a lost
    motion, a cubic term, a knot); a ripple, a hysteresis state or a damping column is not."""
    return bool(cand.basis) and all(_twist_only(b) for b in cand.basis)


def _harmonics(cand: Candidate) -> list[dict]:
    """The group's sin / cos factors (the angle's harmonic, re-timing included)."""
    return [next(f for f in b["factors"] if f.get("op") in ("sin", "cos")) for b in cand.basis]


def modulated_basis(cand: Candidate, law_specs: list[dict], weights: np.ndarray) -> list[dict]:
    """``[f(w) sin(k theta_m), f(w) cos(k theta_m)]`` with f = sum_i weights_i law_specs_i."""
    f = {"op": "sum", "terms": [dict(s) for s in law_specs], "weights": [float(w) for w in weights]}
    return [{"op": "prod", "factors": [dict(h), dict(f)]} for h in _harmonics(cand)]


def _als(y: np.ndarray, Xo: np.ndarray, law: np.ndarray, H: np.ndarray, law_pos: list[int], rows: np.ndarray,
         w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Alternating least squares of y ~ Xo c + (law @ w) * H e on ``rows``: returns (w, [c, e])."""
    w = np.asarray(w0, float)
    coef = None
    for _ in range(ALS_ROUNDS):
        X = np.column_stack([Xo[rows], (law[rows] @ w)[:, None] * H[rows]])
        coef = scaled_lstsq(X, y[rows])
        w_new = coef[law_pos]
        if np.allclose(w_new, w, rtol=1e-6, atol=0.0):
            w = w_new
            break
        w = w_new
    return w, coef


def refine_stiffness_modulation(cand: Candidate, Xo: np.ndarray, law_pos: list[int], law_specs: list[dict],
                                rows_sig, y: np.ndarray, block: np.ndarray, min_gain: float, fold_majority: float,
                                ) -> tuple[bool, list[str]]:
    """Read the selected linear stiffness ripple ``cand`` on the model's identified torsion law.

    ``Xo``: the other selected columns on the shape rows (``y``, ``block``); ``law_pos``: which of them are the torsion
    law, with ``law_specs`` their basis specs (same order); ``rows_sig``: the signals on those rows. Returns
    (changed, statements); when the modulated ripple replaces the linear one, ``cand`` is rebuilt."""
    if not law_pos:
        return False, []
    H = basis_matrix(_harmonics(cand), rows_sig)
    law = Xo[:, law_pos]
    X_lin = np.column_stack([Xo, basis_matrix(cand.basis, rows_sig)])
    every = np.ones(len(y), bool)
    c_lin = scaled_lstsq(X_lin, y)
    w_hat, coef = _als(y, Xo, law, H, law_pos, every, c_lin[law_pos])
    e_s, e_c = coef[-2:]
    eps, psi = harmonic_amplitude_phase(e_s, e_c)
    # leave-one-block-out residuals of both readings; the modulated one with the law's weights refitted per fold
    blocks, inv = np.unique(block, return_inverse=True)
    r_lin = np.empty_like(y)
    r_mod = np.empty_like(y)
    for b in range(len(blocks)):
        tr, te = inv != b, inv == b
        c = scaled_lstsq(X_lin[tr], y[tr])
        r_lin[te] = y[te] - X_lin[te] @ c
        w_b, c_b = _als(y, Xo, law, H, law_pos, tr, c[law_pos])
        r_mod[te] = y[te] - np.column_stack([Xo[te], (law[te] @ w_b)[:, None] * H[te]]) @ c_b
    sse_l, sse_m = np.bincount(inv, r_lin**2), np.bincount(inv, r_mod**2)
    gain = float((sse_l.sum() - sse_m.sum()) / sse_l.sum()) if sse_l.sum() > 0 else 0.0
    folds = float(np.mean(sse_m < sse_l))
    ks = _kstr(cand.order)
    head = (f"position-dependent stiffness (order {ks}) read on the identified torsion law "
            f"({len(law_pos)} law columns; alternating least squares, leave-one-block-out residuals with the law "
            f"refitted per fold, {len(y)} rows): eps_{ks} = {eps:.3g} of the law, CV error {-gain:+.1%} against "
            f"the linear ripple K eps w, lower in {folds:.0%} of the blocks")
    if gain < min_gain or folds < fold_majority:
        cand.nonlinear["law_modulation_tried"] = float(eps)
        why = f"CV gain {gain:.1%} < {min_gain:.0%}" if gain < min_gain else \
            f"lower in {folds:.0%} of the blocks < {fold_majority:.0%}"
        return False, [f"{head}: the linear ripple is kept ({why})"]
    basis = modulated_basis(cand, law_specs, w_hat)
    cand.basis = basis
    cand.level_carrier = dict(basis[0]["factors"][1])
    cand.nonlinear["law_modulated"] = 1.0

    def to_parameters(c, ks=ks):
        a, p = harmonic_amplitude_phase(c[0], c[1])
        return {f"eps_{ks}": a, f"phase_{ks}": p}

    cand.to_parameters = to_parameters
    cand.form = (f"eps_{ks} f(w) sin({ks} theta_m + psi_{ks}), f the identified torsion law (its weights fixed in "
                 "the basis), w = theta_m/N - theta_f: the mesh stiffness's ripple scales the whole law")
    return True, [f"{head}: the ripple on the law replaces the linear one; the selection is made again with it"]
