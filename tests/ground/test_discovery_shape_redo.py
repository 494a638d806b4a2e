"""The rule that triggers discover's redo of candidates and selection (issue 10, disc26): a selected group's final
shape moved from its selection-time value by more than its own SD (the friction width's rule)."""
import numpy as np

from hd_ground.discovery.core import moved_shapes
from hd_ground.discovery.library import Candidate
from hd_twin.identify import Shape


def _dead_zone(j, j_sd, nuisance=()):
    c = Candidate(name="backlash", family="backlash", variable="windup", order=None, basis=[], form="dz(w, j)",
                  shapes=[Shape("j", 1e-5, 1e-3)], make_basis=lambda sh: [{"op": "var", "var": "windup"}],
                  nuisance=nuisance)
    c.set_shape({"j": j}, {"j": j_sd})
    return c


def test_moved_beyond_sd_triggers_and_within_sd_does_not():
    # seed 3100's case: selected at 4.2e-4 (baseline only), final 1.37e-4 +- 1.1e-5: moved by 26 SD
    groups = [(_dead_zone(1.37e-4, 1.1e-5), [3]), (_dead_zone(2.41e-4, 3e-5), [4])]
    at_sel = {0: {"j": 4.2e-4}, 1: {"j": 2.66e-4}}  # the second moved by 0.8 SD: not judged moved
    m = moved_shapes(groups, [0, 1], at_sel)
    assert list(m) == [0]
    assert "0.00042 -> 0.000137" in m[0][0]


def test_nuisance_unselected_and_unknown_sd_are_not_judged():
    g_nuis = (_dead_zone(1.0e-4, 1e-6, nuisance=("j",)), [3])
    g_nosd = (_dead_zone(1.0e-4, float("nan")), [4])
    g_unsel = (_dead_zone(1.0e-4, 1e-6), [5])
    at_sel = {0: {"j": 5e-4}, 1: {"j": 5e-4}, 2: {"j": 5e-4}}
    assert moved_shapes([g_nuis, g_nosd, g_unsel], [0, 1], at_sel) == {}
    assert list(moved_shapes([g_nuis, g_nosd, g_unsel], [2], at_sel)) == [2]
    assert np.isfinite(g_unsel[0].nonlinear["j_sd"])


def test_redo_path_on_a_dead_zone_with_a_position_error():
    """A dead zone (half width 3e-4 rad) and a position error inside the spring (order 2, 4e-5 rad, seed 3100's
    scales): the dead zone's width moves beyond its SD between selection and the final model, so the redo runs; it
    must keep the true groups (dead zone + the order-2 error, which acts only through the contact: the plain ripple
    and its part inside the lost motion, ``theta_m:2:contact``) and say what it did. (At 1.5e-4 rad the redo ran
    until the contact group joined the model: with it the width no longer moves.)"""
    from hd_ground.discovery.core import discover_signal

    from .synthetic import torsion_plant

    j = 3e-4
    ds, ho = torsion_plant(lambda x: 1e6 * np.sign(x) * np.maximum(np.abs(x) - j, 0),
                           lambda th: 4e-5 * np.sin(2 * th + 0.4), 1)
    r = discover_signal(ds, "Q_red", ho)
    assert any("a selected shape moved in the final model beyond its SD" in s for s in r.statements)
    assert sorted((e["name"], e["order"]) for e in r.effects) == [
        ("backlash", None), ("kinematic_error_harmonic", 2), ("kinematic_error_harmonic", 2)]
    assert all("K a_" not in e["form"] for e in r.effects)  # the plain ripple and its contact part, no load variant
    assert any("1[|w| < j]" in e["form"] for e in r.effects)
    assert r.error_after["rmse"] < r.error_before["rmse"]
