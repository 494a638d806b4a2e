"""Knots of the catalogue's piecewise-linear torsion law as candidates, and a part of an effect that takes its partner's
identification goes before the partner (issue 10, thirty-third pass).

Found on `hdphm bench discover --all` at seed 17300 (default family, assembly backlash j0 = 1 arcmin; 4 missions x
4 s, the last held out): discover modelled the twist-to-torque law beyond the dead zone by K_j dz + k3_j dz^3 and
then powers of the *measured* twist (k3 w^3, k5 w^5), held-out Q_red 2.493 N*m, while the plain greedy reference
stacked three dead zones of different widths, 2.266 (z +3.3, the same against the fit-CV greedy): a piecewise-linear
law, which is what the catalogue's three-slope curve is (PHYSICS.md 2.1), and what a polynomial in w bends from zero
to reach (a dead zone shifts the curve's curvature to |w| ~ j + u). Its second dead zone, added to discover's final
model, lowered the fit blocks' CV error by 12 % in 93 % of the blocks: the fit data support it.

``library.torsion_knot_candidates``: a knot dK dz(w; u) with u identified by the CV profile, a refinement competing
once the lost motion is selected and needing it beside it in the final model; a second knot
after the first. On the case: held-out 2.291 (z +2.1 against greedy). The thirty-fifth pass's rounded dead zone
then read what was left, the gap's soft corners (2.207), and no knot is admitted there any more (the last test).

With it, ``core.select_groups``' final identification check met a new situation: on deadzone-lugre hysteresis the
knot entered at a width inside the lost motion, the dead zone became unidentified beside it and was dropped, and the
knot, orphaned, went after it: held-out 93.6 against 15.3 before. A part of an effect (``Candidate.beside``) that
takes its partner's identification is now dropped first, and the partner asked again without it.
"""

import numpy as np

from hd_ground.discovery.core import Options, _BlockGram, select_groups
from hd_ground.discovery.library import Candidate, LibraryContext, build_candidates

from .bench_module import bd


def test_knots_refine_a_selected_law_and_need_it_beside_them():
    ctx = LibraryContext(target="Q_red", available={"theta_m", "windup", "omega_m", "theta_f"}, omega_scale=10.0,
                         omega_low=1.0, sgn_eps=0.1, t_ref=25.0, orders={"theta_m": [1.0, 2.0]},
                         windup_scale=1e-3, windup_noise=1e-6)
    knots = [c for c in build_candidates(ctx) if c.family.startswith("stiffness:knot")]
    assert {(c.family, c.after) for c in knots} == {("stiffness:knot", "backlash"), ("stiffness:knot2", "stiffness:knot")}
    for c in knots:
        assert c.name == "nonlinear_stiffness" and c.beside == c.after
        assert [s.name for s in c.shapes] == ["u"] and c.shapes[0].lo >= 1e-6 and c.shapes[0].hi <= 1e-3
        b = c.make_basis({"u": 2e-4})
        assert b == [{"op": "deadzone", "var": "windup", "width": 2e-4}]
    # the tau_m library has none
    assert not [c for c in build_candidates(LibraryContext(target="tau_m", available={"omega_m", "windup"},
                                                           omega_scale=10.0, omega_low=1.0, sgn_eps=0.1, t_ref=25.0,
                                                           orders={}, windup_scale=1e-3, windup_noise=1e-6))
                if c.family.startswith("stiffness:knot")]


def test_a_part_that_takes_its_partners_identification_is_dropped_before_the_partner():
    # y is d alone; a (the partner) is most of d, so it enters first, and d (a part that needs a beside it) after it.
    # In the final model a's coefficient is nothing: the old rule dropped a as unidentified and d as its orphan,
    # leaving the baseline; the part goes first now, and a, asked again alone, stays
    rng = np.random.default_rng(3)
    n = 6000
    a = rng.standard_normal(n)
    d = a + 0.3 * rng.standard_normal(n)
    y = d + 0.05 * rng.standard_normal(n)
    X = np.stack([np.ones(n), a, d], 1)
    gram = _BlockGram(X, y, np.repeat(np.arange(15), n // 15))
    part = Candidate("nonlinear_stiffness", "part", "windup", None, [], "d", after="partner", beside="partner")
    partner = Candidate("backlash", "partner", "windup", None, [], "a")
    sel, trace = select_groups(gram, [0], [(partner, [1]), (part, [2])], Options())
    steps = [r["step"] for r in trace]
    assert "drop (takes its partner's identification)" in steps, trace
    assert sel == [0], trace  # the partner kept: a model, not the bare baseline
    assert "drop (without its partner)" not in steps


def test_default_backlash_at_17300_reads_the_gaps_rounded_edge(tmp_path):
    # the row the knots were built for: hd_sim's gap has softplus corners. The knots beyond the hard zone took it from
    # 2.493 to 2.291 (greedy's three stacked dead zones 2.266); the rounded zone (thirty-fifth pass, edgeshape) reads
    # the corners themselves, and with it neither a knot nor an odd power of the twist is admitted
    effect = "backlash"
    params, exp1 = bd.FAMILY_EFFECTS[effect]
    bags = bd.make_family_bags(tmp_path / "bags", "default", effect, params, duration=4.0, seed=17300)
    row = bd.evaluate_world_case("default", effect, bags, (exp1,), None, tmp_path / "out", signals=["Q_red"])
    import json

    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    q = next(s for s in rep["signals"] if s["signal"] == "Q_red")
    assert any(r["step"] == "edge shape" for r in q["selection_trace"]), q["selection_trace"]
    assert row["found_right"], row["found"]
    gap = next(t for t in q["terms"] if t["name"] == "backlash")["parameters"]
    assert gap["edge_used"] == 1.0 and gap["edge_ratio_se"] < 0.2 * gap["edge_ratio"], gap
    assert row["after"] < row["greedy_after"], (row["after"], row["greedy_after"], row["paired_z"])


def test_the_premises_on_the_lost_motions_width():
    from hd_ground.discovery.core import _beyond_holds, _shape_premise_holds
    from hd_twin.identify import Shape

    def dz(j, sd):
        c = Candidate("backlash", "backlash", "windup", None, [], "dz", shapes=[Shape("j", 2.5e-7, 1.5e-3)],
                      make_basis=lambda sh: [])
        c.set_shape({"j": j}, {"j": sd})
        return c

    knot = Candidate("nonlinear_stiffness", "stiffness:knot", "windup", None, [], "dK dz(w; u)",
                     needs_shape=("backlash", "j"), beyond=("backlash", "j", "u"), nonlinear={"u": 2e-4})
    need = knot.needs_shape
    # a gap: 1.6e-4 +- 9e-7 (default backlash, seed 17300)
    assert _shape_premise_holds([(dz(1.6e-4, 9e-7), [3])], [0], need)
    # the reidentify synthetic (a smooth law, no gap): 3.0e-7 +- 8.4e-8 at the low end of its range (2.5e-7)
    assert not _shape_premise_holds([(dz(3.0e-7, 8.4e-8), [3])], [0], need)
    assert not _shape_premise_holds([(dz(1.6e-4, float("nan")), [3])], [0], need)  # no SD: nothing known
    assert not _shape_premise_holds([(dz(1.6e-4, 9e-7), [3])], [], need)  # the lost motion not selected
    groups = [(dz(1.6e-4, 9e-7), [3]), (knot, [4])]
    assert _beyond_holds(groups, [0], 1)
    knot.nonlinear["u"] = 1.1e-4  # inside the gap: a soft edge, not a knot of the law
    assert not _beyond_holds(groups, [0], 1)
