"""A shaped group is judged at its shape given the final model before it is dropped as unidentified (issue 10).

Found on smooth-cubic kinematic error, fresh seed 9100 (`hdphm bench discover`'s case, 4 missions x 4 s, the last
held out): discover selected a dead zone first (its width profiled with nothing else in the model: 4.6e-5 rad, CV
gain 87 %), then the kinematic error, its w^2 ripple and the cubic law. Beside the cubic law the dead zone's
jackknife Wald statistic was 11.29 against the 3-sigma threshold of 11.83, and the final identification prune
dropped it at the width it had entered with; the model left scored 5.327 N*m on the held-out bag against the plain
greedy reference's 3.937 (z +4.8), although the dead zone lowered the fit blocks' CV error in all 15 blocks.

``core.select_groups`` now re-identifies such a group's shape given all the other selected groups first (variable
projection: a shape profiled beside the groups before it is not the shape's estimate in a model that holds groups
added after it), records it as ``reshape (unidentified)`` and asks again at that shape; the final-shape check then
asks whether the new shape is identified, as for every shaped group. On this case the width runs to the lower bound
of its range (the data only bound it), the dead-zone family is closed as unidentified, and the selection made again
without it finds the cubic law with a quintic correction, the kinematic error and its load ripple: held-out 3.713,
below greedy's. This is the case the rule was found on (a regression test); the bench's other cases were run
with the rule (README, discovery section), and it fired on no other. Since the thirtieth pass (the torsion law's
k2 w |w| term) this case takes another path to the same end (the dead zone left out at its lower width bound), so
the test runs with the catalog the rule was found with.

~20 s (bags 10 s, discover and greedy 10 s).
"""

import json

from .bench_module import bd


def test_a_dead_zone_unidentified_beside_the_cubic_law_is_reshaped_then_left_out(tmp_path, monkeypatch):
    # the catalog as the rule was found with: the thirtieth pass's quadratic torsion term k2 w |w| takes another path
    # on this case (it replaces the cubic as a confounded reading, and the dead zone's shape fails the final-shape
    # check directly: held-out 3.954 against greedy's 3.936, z +0.19), so it is left out here to keep the rule under test
    import hd_ground.discovery.core as core

    build = core.build_candidates
    monkeypatch.setattr(core, "build_candidates", lambda ctx: [c for c in build(ctx) if c.family != "stiffness:2"])
    effect = "kinematic_error_harmonic"
    params, exp1 = bd.FAMILY_EFFECTS[effect]
    bags = bd.make_family_bags(tmp_path / "bags", "smooth-cubic", effect, params, duration=4.0, seed=9100)
    row = bd.evaluate_world_case("smooth-cubic", effect, bags, (exp1,), None, tmp_path / "out", signals=["Q_red"])
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    q = next(s for s in rep["signals"] if s["signal"] == "Q_red")
    steps = [r for r in q["selection_trace"] if r["step"] == "reshape (unidentified)"]
    assert steps and steps[0]["candidate"] == "backlash[backlash]", [r["step"] for r in q["selection_trace"]]
    assert steps[0]["wald_before"] < 11.83  # the knife edge it would have been dropped on
    assert steps[0]["shape"]["j"] < 4.6e-5  # given the cubic law the width shrinks towards nothing
    # the dead zone at its new width is not identified (the data only bound it): left out, selection made again
    assert any("backlash" in s and "not identified" in s for s in q["statements"]), q["statements"]
    assert not any(t["name"] == "backlash" for t in q["terms"])
    assert row["found_right"], row["found"]
    # held-out Q_red no higher than the greedy reference's (before the rule: 5.327 against 3.937, z +4.8)
    assert row["after"] <= row["greedy_after"], (row["after"], row["greedy_after"], row["paired_z"])
    assert row["after"] < 0.8 * 5.327
