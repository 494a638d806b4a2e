"""The lost motion's edge, identified from data (issue 10: "dead-zone width" and the shape around it).

The twist-side lost motion (``library.twist_shape_candidates``) enters the selection as a hard dead zone,
``K_j dz(w; j) + k3_j dz(w; j)^3`` with ``dz = sgn(w) max(|w| - j, 0)``: the teeth take up load at once at |w| = j.
A real gap closes over a range of twist: the flanks' profile errors and the tooth-to-tooth spread of the gap bring
the teeth into contact one after another, so the torque rises through a rounded corner. Here the selected dead zone
is given corners of width s (``hd_twin.terms``' ``deadzone`` op with ``edge``: softplus corners, s -> 0 the hard
zone) and the pair (j, s / j) is identified by variable projection on the leave-one-block-out residuals
(``hd_twin.identify.vp_shape``: the coefficients of every selected column projected out, a block-robust sandwich SE
per shape), from two starts (a sharp and a round corner).

The rounded zone **replaces** the hard one only by the selection's own rules: s / j identified (its SE under its size
and the optimum off the searched range's bounds), and the fit blocks' CV error lower by ``min_gain`` in a majority
(``fold_majority``) of the blocks. The selection is then made again with it (s / j fixed, j searched), so a knot of
the torsion law or a contact ripple competes beside the rounded zone as it did beside the hard one. Otherwise the
hard zone stays and the edge is reported (a statement; the term's ``edge_ratio_tried``, ``edge_ratio_se`` and
``edge_used`` 0).

Why a separate step and not a second variant of the backlash family: variants of a family that explain the data
within 10 % of the best one's improvement are one reading (the library's first is kept), and a dead zone's
improvement is most of the twist's error, so an edge worth a few % of the rest could never be told from it there.
"""

from __future__ import annotations

import numpy as np

from hd_twin.identify import Shape, cv_residuals, vp_shape

from .library import Candidate

#: the edge width's searched range, as a fraction of the gap's half-width j (hd_sim's corner is 0.05 j; one of j is
#: a corner as wide as the gap itself, the end of a dead zone's reading)
EDGE_RATIO_RANGE = (0.005, 1.0)


def is_hard_dead_zone(cand: Candidate) -> bool:
    """A selected lost motion with sharp corners (the backlash family's hard dz(w; j) law)."""
    return (cand.name == "backlash" and bool(cand.shapes) and cand.shapes[0].name == "j"
            and "edge_ratio" not in cand.nonlinear
            and all(b.get("op") == "prod" and all(f.get("op") == "deadzone" for f in b["factors"]) for b in cand.basis))


def _rounded_basis(j: float, r: float) -> list[dict]:
    d = {"op": "deadzone", "var": "windup", "width": float(j), "edge": float(r * j)}
    return [{"op": "prod", "factors": [dict(d)]}, {"op": "prod", "factors": [dict(d), dict(d), dict(d)]}]


def refine_dead_zone_edge(cand: Candidate, design_of, y: np.ndarray, block: np.ndarray, min_gain: float,
                          fold_majority: float, max_nfev: int = 40) -> tuple[bool, list[str]]:
    """Identify the selected dead zone's edge (j, s / j) given the other selected columns.

    ``design_of(make_basis)`` returns ``design(shape) -> X`` (the other columns plus this group's basis from
    ``make_basis(shape)``) on the shape rows ``y`` / ``block``. Returns (changed, statements); when the rounded zone
    replaces the hard one, ``cand`` is rebuilt with s / j fixed at its estimate and j still searched."""
    if not is_hard_dead_zone(cand):
        return False, []
    sj = cand.shapes[0]
    j0 = float(cand.nonlinear.get("j", np.sqrt(sj.lo * sj.hi)))
    design = design_of(lambda sh: _rounded_basis(sh["j"], sh.get("r", 0.0)))
    shapes = [Shape("j", sj.lo, sj.hi, log=True), Shape("r", *EDGE_RATIO_RANGE, log=True)]
    # the reference: the hard zone at its own least-squares optimum of the same CV objective (j only)
    try:
        vh = vp_shape(y, lambda sh: design({"j": sh["j"], "r": 0.0}), block, shapes[:1], {"j": j0}, refine=True,
                      max_nfev=max_nfev)
        j0 = float(vh.shape["j"])
    except (np.linalg.LinAlgError, ValueError):
        pass
    r_hard = cv_residuals(y, design({"j": j0, "r": 0.0}), block)
    fits = []
    for r0 in (0.03, 0.3):
        try:
            fits.append(vp_shape(y, design, block, shapes, {"j": j0, "r": r0}, refine=True, max_nfev=max_nfev))
        except (np.linalg.LinAlgError, ValueError):
            continue
    if not fits:
        return False, ["lost motion's edge: not computed (singular design); the hard dead zone is kept"]
    best = min(fits, key=lambda f: f.cv_rmse)
    r_soft = cv_residuals(y, design(best.shape), block)
    inv = np.unique(block, return_inverse=True)[1]  # per-block SSE of each zone's CV residuals
    sse_h, sse_s = np.bincount(inv, r_hard**2), np.bincount(inv, r_soft**2)
    gain = float((sse_h.sum() - sse_s.sum()) / sse_h.sum()) if sse_h.sum() > 0 else 0.0
    folds = float(np.mean(sse_s < sse_h))
    sh, se = dict(best.shape), dict(best.se)
    cand.nonlinear["edge_ratio_se"] = float(se["r"])
    cand.nonlinear["edge_ratio_weak"] = float("r" in best.weak)
    head = (f"lost motion's edge (softplus corners of width s; variable projection on the leave-one-block-out "
            f"residuals, sandwich SEs, {len(y)} rows): j = {sh['j']:.3g} +- {se['j']:.2g} rad, s / j = {sh['r']:.3g} "
            f"+- {se['r']:.2g}; CV error {-gain:+.1%} against the hard zone (j = {j0:.3g}), lower in {folds:.0%} of "
            "the blocks")
    if "r" in best.weak or gain < min_gain or folds < fold_majority:
        why = (f"s / j weakly identified ({'; '.join(best.notes)})" if "r" in best.weak else
               f"CV gain {gain:.1%} < {min_gain:.0%}" if gain < min_gain else
               f"lower in {folds:.0%} of the blocks < {fold_majority:.0%}")
        cand.nonlinear["edge_used"] = 0.0
        cand.nonlinear["edge_ratio_tried"] = float(sh["r"])  # the law stays hard: no edge_ratio (is_hard_dead_zone)
        return False, [f"{head}: the hard dead zone is kept ({why})"]
    r_hat = float(sh["r"])

    def rounded(s):
        return _rounded_basis(s["j"], r_hat)

    cand.make_basis = rounded
    cand.basis = rounded({"j": float(sh["j"])})
    cand.nonlinear["edge_ratio"] = r_hat
    cand.nonlinear["j"] = float(sh["j"])
    cand.nonlinear["j_se_joint"] = float(se["j"])
    cand.nonlinear["edge_used"] = 1.0
    cand.form = ("K_j dz_s(w; j) + k3_j dz_s(w; j)^3, dz_s the dead zone of half-width j with softplus corners of "
                 f"width s = {r_hat:.3g} j (teeth taking up load over a range of twist), w = theta_m/N - theta_f")
    return True, [f"{head}: the rounded dead zone replaces the hard one; the selection is made again with it "
                  "(s / j fixed, j searched)"]
