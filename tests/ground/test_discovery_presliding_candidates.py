"""Direction-dependent candidates exist when the baseline's friction follows a pre-sliding state (issue 10).

Where discovery identifies a rate-independent pre-sliding transition (Dahl / LuGre bristle state) as the friction
direction, the sgn-modulated ripple ``F_k sin(k theta_m + rho_k) s`` rides on that state: its basis names the derived
column ``presliding:theta_m:...``. The candidate used to list that column among the signals it requires, and since
discovery makes the column itself, no bag ever "had" it: every position-periodic friction candidate was silently
dropped on every plant with a pre-sliding baseline. `hdphm bench discover --extra --all` showed it (seed 100,
deadzone-lugre, F_2 = 0.8 N*m at order 2): discover found nothing, held-out 0.5376 N*m, while the plain greedy search
named the effect (0.3382). A candidate now requires the logged signal under a derived column
(``library.measured_signal``).

~20 s (bags 5 s, discover on tau_m 15 s).
"""

from hd_ground.discovery.library import LibraryContext, build_candidates, measured_signal, state_var

from .bench_module import bd

_AVAIL = {"theta_m", "theta_f", "omega_m", "omega_f", "Q_red", "i_q", "temperature", "tau_m"}


def _ctx(fric_spec):
    return LibraryContext(target="tau_m", available=set(_AVAIL), omega_scale=10.0, omega_low=1.0, sgn_eps=0.05,
                          t_ref=25.0, fric_spec=fric_spec, orders={"theta_m": [1.0, 2.0, 4.0]})


def test_the_candidates_do_not_depend_on_which_friction_direction_the_baseline_chose():
    state = {"op": "var", "var": state_var("theta_m", 1e-3) + ":0.55"}
    assert measured_signal(state["var"]) == "theta_m" and measured_signal("omega_m") == "omega_m"
    with_tanh = build_candidates(_ctx(None))
    with_state = build_candidates(_ctx(state))
    names = lambda cs: sorted((c.name, c.family) for c in cs)  # noqa: E731
    assert names(with_state) == names(with_tanh)
    ppf = [c for c in with_state if c.name == "position_periodic_friction"]
    assert sorted(c.order for c in ppf) == [1.0, 2.0, 4.0]
    for c in ppf:
        assert set(c.requires) <= _AVAIL, c.requires
        assert state["var"] in repr(c.basis)  # the ripple rides on the baseline's state, not on a tanh


def test_position_periodic_friction_is_found_on_a_lugre_plant(tmp_path):
    from hd_ground.discovery.core import Options
    from hd_ground.discovery.pipeline import run_discovery

    params, _ = bd.FAMILY_EFFECTS["position_periodic_friction"]
    bags = bd.make_family_bags(tmp_path / "bags", "deadzone-lugre", "position_periodic_friction", params,
                               duration=4.0, seed=100)
    rep = run_discovery([str(b) for b in bags], tmp_path / "out", heldout=[str(bags[-1])], plots=False,
                        within_bag_check=False, signals=["tau_m"], log=lambda s: None,
                        opt=Options(alpha_window=bd.ALPHA_WINDOW, retime_window=bd.RETIME_WINDOW))
    t = next(s for s in rep["signals"] if s["signal"] == "tau_m")
    assert "presliding_distance" in t["baseline_parameters"]  # the case the bug hid: a pre-sliding baseline
    first = t["effects"][0]
    assert (first["name"], first["variable"], first["order"]) == ("position_periodic_friction", "theta_m", 2.0), \
        t["effects"]
    assert t["error_after"]["rmse"] <= 0.6 * t["error_before"]["rmse"], (t["error_before"], t["error_after"])
