"""Discovery on plants we did not build it around: hd_sim structural families and the independent plant2.

For one hidden effect per world, ``hdphm discover``'s core must name it and leave a held-out error no higher
than the plain greedy least-squares reference (``hd_ground.discovery.greedy``: what an engineer writes in an
afternoon, scored on the same held-out bag it selects on) in the same run; on clean data it must report
nothing that explains >= 5 % of the held-out residual on any signal (a finding that is the world's own
torsion law on Q_red, e.g. the Bouc-Wen loop of hysteretic-robot, is not an undeclared effect).

Clean deadzone-lugre is asserted too: its former omega_m |omega_m| finding (~11 % explained, greedy found it
as well) was the simulator's sampled command-staircase bias at a 2 kHz simulation rate, gone since the bench
simulates every family at >= 4 kHz (bench_discover.make_family_bags). Bags come from the session fixtures (short missions,
built once); the evaluation is ``bench/bench_discover.py``'s (``hdphm bench discover`` prints the same rows
for every catalog effect on every family).
"""

import pytest

from .bench_module import bd

#: (world, hidden effect): one per world (hdphm bench discover prints every catalog effect on every family)
CASES = [
    ("default", "stribeck_friction"),
    ("smooth-cubic", "position_periodic_torque"),
    ("deadzone-lugre", "stribeck_friction"),  # LuGre pre-sliding friction: needs the identified transition law
    ("hysteretic-robot", "stribeck_friction"),
    ("plant2", "load_friction"),
]


#: Cases where the paired held-out check cannot separate discover from greedy's held-out luck; the other assertions
#: still hold and the check runs (a pass passes). smooth-cubic position-periodic torque on these bags (seed 0), with
#: the identified acceleration window (5 ms + timing): discover's friction width 1.16 +- 0.03 rad/s against the
#: simulator's 1.077 (the 20 ms window gave 1.48 +- 0.16), held-out 0.1388 N*m (0.1407 with 20 ms), greedy on the same
#: signals 0.1382 at its grid width 0.922; the simulator's own width with least-squares coefficients and the same
#: terms scores 0.13837, z +6.8 against greedy: within one held-out bag a wrong width can win by 0.1-0.4 %
#: systematically (README, discovery section; docs/DISCOVERY_PASSES.md, eighth pass).
#: plant2 load friction (8 s bags, seed 0), since the twenty-third pass (the width profiled on the filtered torque
#: balance): discover's model is load-dependent friction on tanh at eps 0.9996 +- 0.0086 rad/s (the plant's v_t is
#: 1.0; before the pass 1.17 +- 0.24 with a spurious Stribeck term, held-out 0.0097349, z +0.2); greedy's has the same
#: two groups at its grid width 1.01. Held-out 0.0097402 vs 0.0097328 (+0.08 %, z +2.4); the fit blocks' CV SSE of the
#: two models differs by 0.02 % (bench/diag_tau_m_vs_greedy.py; docs/DISCOVERY_PASSES.md, twenty-third pass).
HELDOUT_BAG_LUCK = {
    ("smooth-cubic", "position_periodic_torque"): "held-out bag favours greedy's grid width over the true one",
    ("plant2", "load_friction"): "held-out bag favours greedy's grid width 1.01 over discover's 1.000 (plant: 1.0)",
}


@pytest.fixture(scope="module")
def family_bags(tmp_path_factory):
    """Bags of a family case with the bench's effect amplitudes and acquisition (4 missions x 4 s), cached."""
    root, cache = tmp_path_factory.mktemp("world_cases"), {}

    def make(world, effect):
        if (world, effect) not in cache:
            params = bd.FAMILY_EFFECTS[effect][0] if effect else {}
            cache[world, effect] = bd.make_family_bags(root / f"{world}_{effect}", world, effect, params,
                                                       duration=4.0)
        return cache[world, effect]

    return make


def _case(world, effect, family_bags, plant2_case_bags, tmp_path, signals=None):
    if world == "plant2":
        c = plant2_case_bags(effect or "clean")
        bags, expect, truth = [str(b) for b in c["bags"]], bd.PLANT2_EXPECT[effect or "clean"], c["truth"]
    else:
        exp1 = bd.FAMILY_EFFECTS[effect][1] if effect else None
        bags, expect, truth = family_bags(world, effect), ((exp1,) if exp1 else ()), None
    sig = signals or ([expect[0][0]] if expect else None)
    return bd.evaluate_world_case(world, effect, bags, expect, truth, tmp_path / "out", signals=sig)


@pytest.mark.parametrize("world, effect", CASES, ids=[f"{w}-{e}" for w, e in CASES])
def test_hidden_effect_named_and_no_worse_than_greedy(world, effect, family_bags, plant2_case_bags, tmp_path):
    r = _case(world, effect, family_bags, plant2_case_bags, tmp_path)
    assert r["found_right"], (r["found"], r["expect"])
    assert r["after"] < r["before"]
    # no higher than the greedy reference's, although the reference picks its terms on the very held-out bag
    # it is scored on (as the afternoon script does): lower, or higher by less than the held-out bag's own
    # sampling noise (discover's held-out MSE above greedy's by < 2 standard errors of the paired difference
    # over 20 contiguous chunks: at the noise floor greedy's held-out-selected extra term buys it < 1 %)
    z = r["paired_z"]
    assert z is not None, "discover and greedy were not scored on the same held-out rows"
    if (world, effect) in HELDOUT_BAG_LUCK and not (r["after"] <= r["greedy_after"] or z < 2.0):
        pytest.xfail(HELDOUT_BAG_LUCK[world, effect] + f" (now {r['after']:.5g} vs {r['greedy_after']:.5g}, z {z:+.1f})")
    assert r["after"] <= r["greedy_after"] or z < 2.0, (r["after"], r["greedy_after"], z)


@pytest.mark.parametrize("world", ["default", "smooth-cubic", "deadzone-lugre", "hysteretic-robot", "plant2"])
def test_clean_data_nothing_explains_5_percent(world, family_bags, plant2_case_bags, tmp_path):
    # every signal (hysteretic-robot's Bouc-Wen twist used to leak into theta_m harmonics of Q_red)
    r = _case(world, None, family_bags, plant2_case_bags, tmp_path, signals=["tau_m", "Q_red"])
    assert r["clean_max_explained"] < 0.05, r["found"]


def test_bench_refuses_unknown_effects_before_running(tmp_path, capsys):
    # "clean" is no catalog effect (every family's clean case always runs): refused by name before any case, not
    # a worker's KeyError minutes in
    assert bd.main(["--family-effects", "clean,cogging_torque", "--no-plant2", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown clean" in err and "cogging_torque" in err
    assert bd.main(["--families", "default,nope", "--no-plant2", "--out", str(tmp_path)]) == 2
    assert "unknown nope" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
