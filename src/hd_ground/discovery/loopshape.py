"""The hysteresis loop's shape, identified from data (issue 10: "hysteresis shape").

The twist-side hysteresis candidate (``library.twist_shape_candidates``) enters the selection as the Dahl state of
the twist (one shape parameter, the distance d_h, by the CV profile). Dahl is one loop shape among many: it leaves
saturation exponentially after a reversal and yields with a fixed sharpness. Here the selected loop's shape is
identified within the normalised **Bouc-Wen** family (``hd_twin.identify.hysteresis_state``), which contains Dahl as
(n = 1, phi = 1) and needs no assumption about the plant:

    ds/dw = [1 - |s|^n] / d_h while |s| grows (loading), [1 + phi |s|^n] / d_h while it shrinks (unloading),

n the sharpness of the yield (large n: elastic-perfectly plastic), phi = (beta - gamma) / (beta + gamma) the
unloading law (0: linear unloading to zero state, beta = gamma; 1: Dahl's exponential; > 1: faster). Why Bouc-Wen
and not a sum of Dahl elements (Maxwell slip): a Maxwell-slip loop obeys Masing's rule (the unloading branch is the
loading branch scaled by two) for any element distribution, so it cannot express a loop whose unloading differs
from its loading, the first thing a measured loop may show; Bouc-Wen's phi is that difference, and n its yield
sharpness, with three parameters in all.

Estimator: variable projection. The coefficients (T_h and every other selected column) are projected out by least
squares on the other blocks for every row, and ``scipy.optimize.least_squares`` minimises the stacked
leave-one-block-out residuals over (log d_h, log n, log(1 + phi)) from two starts (Dahl, and linear unloading); the
uncertainty is the block-robust sandwich of ``hd_twin.identify.vp_shape`` (an SE per parameter, "weak" when it
exceeds the parameter's size or the optimum sits on a bound). The identified shape **replaces** Dahl's only when n
and phi are both identified and the cross-validated error falls by the selection's ``min_gain`` (the rule every
other law choice follows, e.g. tanh vs the pre-sliding state of the friction); otherwise the Dahl loop stays and
the shape is reported with its SEs (a statement and the term's parameters ``n_h``, ``phi_h`` and their SEs).
"""

from __future__ import annotations

import numpy as np

from hd_twin.identify import BW_N_RANGE, BW_PHI_RANGE, Shape, cv_residuals, vp_shape

from .library import STATE_PREFIX, Candidate, measured_signal


def loop_state_var(var: str, distance: float, n: float, phi: float) -> str:
    """Column name of the Bouc-Wen state of ``var`` (``StateSignals`` computes it on demand)."""
    return f"{STATE_PREFIX}{var}:{float(distance)!r}:{float(n)!r}:{float(phi)!r}"


def twist_state_of(cand: Candidate) -> str | None:
    """The twist variable whose Dahl state a selected hysteresis group rides on (None: not such a group)."""
    if cand.name != "hysteresis" or len(cand.basis) != 1 or not cand.shapes or cand.shapes[0].name != "d_h":
        return None
    v = str(cand.basis[0].get("var", ""))
    if cand.basis[0].get("op") != "var" or not v.startswith(STATE_PREFIX) or len(v.split(":")) != 3:
        return None
    return measured_signal(v)


def refine_loop_shape(cand: Candidate, design_of, y: np.ndarray, block: np.ndarray, min_gain: float,
                      max_nfev: int = 40) -> tuple[bool, list[str]]:
    """Identify the selected hysteresis group's loop shape (d_h, n, phi) given the other selected columns.

    ``design_of(make_basis)`` returns ``design(shape) -> X`` (the other columns plus this group's basis from
    ``make_basis(shape)``) on the shape rows ``y`` / ``block``. Returns (changed, statements); when the shape
    replaces Dahl's, ``cand`` is rebuilt with (n, phi) fixed at their estimates and d_h still searched (the
    selection is then made again), and its parameters carry ``n_h``, ``phi_h`` and their sandwich SEs.
    """
    var = twist_state_of(cand)
    if var is None:
        return False, []
    d0 = float(cand.nonlinear.get("d_h", np.sqrt(cand.shapes[0].lo * cand.shapes[0].hi)))
    sd = cand.shapes[0]

    # searched as q_h = 1 + phi (the unloading slope at saturation over the slope at s = 0: Dahl 2, linear
    # unloading 1) on a log scale: phi may be 0 (or change sign), its SE is judged against q_h's e-folds
    def bw_basis(sh):
        return [{"op": "var", "var": loop_state_var(var, sh["d_h"], sh["n_h"], sh["q_h"] - 1.0)}]

    design = design_of(bw_basis)
    shapes = [Shape("d_h", sd.lo, sd.hi, log=True), Shape("n_h", *BW_N_RANGE, log=True),
              Shape("q_h", 1.0 + BW_PHI_RANGE[0], 1.0 + BW_PHI_RANGE[1], log=True)]
    # the reference: the Dahl loop at its own least-squares optimum of the same CV objective (d_h only)
    try:
        vd = vp_shape(y, lambda sh: design({"d_h": sh["d_h"], "n_h": 1.0, "q_h": 2.0}), block, shapes[:1],
                      {"d_h": d0}, refine=True, max_nfev=max_nfev)
        d0 = float(vd.shape["d_h"])
    except (np.linalg.LinAlgError, ValueError):
        pass
    dahl = {"d_h": d0, "n_h": 1.0, "q_h": 2.0}
    r_dahl = cv_residuals(y, design(dahl), block)
    sse_dahl = float(np.sum(r_dahl**2))
    fits = []
    for start in (dahl, {"d_h": d0, "n_h": 1.0, "q_h": 1.0}):
        try:
            fits.append(vp_shape(y, design, block, shapes, start, refine=True, max_nfev=max_nfev))
        except (np.linalg.LinAlgError, ValueError):
            continue
    if not fits:
        return False, [f"hysteresis loop shape: not computed (singular design); the Dahl loop is kept"]
    best = min(fits, key=lambda f: f.cv_rmse)
    sse_bw = best.cv_rmse**2 * len(y)
    gain = (sse_dahl - sse_bw) / sse_dahl if sse_dahl > 0 else 0.0
    sh, se = dict(best.shape), dict(best.se)
    sh["phi_h"], se["phi_h"] = sh.pop("q_h") - 1.0, se.pop("q_h")
    best.weak = ["phi_h" if k == "q_h" else k for k in best.weak]
    txt = (f"d_h = {sh['d_h']:.3g} +- {se['d_h']:.2g} rad, n = {sh['n_h']:.3g} +- {se['n_h']:.2g}, "
           f"phi = {sh['phi_h']:.3g} +- {se['phi_h']:.2g}")
    for k in ("n_h", "phi_h"):
        cand.nonlinear[k] = float(sh[k])
        cand.nonlinear[f"{k}_se"] = float(se[k])
        cand.nonlinear[f"{k}_weak"] = float(k in best.weak)
    dahl_z = abs(sh["phi_h"] - 1.0) / se["phi_h"] if se["phi_h"] > 0 else float("inf")
    head = (f"hysteresis loop shape (Bouc-Wen family, Dahl = n 1 / phi 1; variable projection on the "
            f"leave-one-block-out residuals, sandwich SEs, {len(y)} rows): {txt}; CV error {gain:+.1%} against the "
            f"Dahl loop; phi is {dahl_z:.1f} SE from Dahl's 1")
    weak = [k for k in ("n_h", "phi_h") if k in best.weak]
    if weak or gain < min_gain:
        why = (f"{', '.join(weak)} weakly identified ({'; '.join(best.notes)})" if weak else
               f"CV gain {gain:.1%} < {min_gain:.0%}")
        cand.nonlinear["loop_shape_used"] = 0.0
        return False, [f"{head}: the Dahl loop is kept ({why})"]
    n_h, phi_h = float(sh["n_h"]), float(sh["phi_h"])

    def fixed_basis(s):
        return [{"op": "var", "var": loop_state_var(var, s["d_h"], n_h, phi_h)}]

    cand.make_basis = fixed_basis
    cand.basis = fixed_basis({"d_h": float(sh["d_h"])})
    cand.nonlinear["d_h"] = float(sh["d_h"])
    cand.nonlinear["d_h_se_joint"] = float(se["d_h"])
    cand.nonlinear["loop_shape_used"] = 1.0
    cand.form = (f"T_h s(w; d_h, n_h, phi_h), ds/dw = [1 - |s|^n_h] / d_h loading, [1 + phi_h |s|^n_h] / d_h "
                 f"unloading (Bouc-Wen state of the twist w = theta_m/N - theta_f{', through a play of one encoder step' if var == 'windup_q' else ''})")
    return True, [f"{head}: the identified loop replaces the Dahl loop; the selection is made again with it "
                  "(n_h, phi_h fixed, d_h searched)"]
