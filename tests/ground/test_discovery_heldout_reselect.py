"""The selection made again after a held-out drop that had displaced groups (core._reselect_without_heldout_drop,
issue 10 twelfth pass). The trigger logic on a selection trace, with select_groups replaced by a recorder; the
bench (smooth-cubic KE, seed 102) is the end-to-end check. Milliseconds."""

from types import SimpleNamespace

import hd_ground.discovery.core as core


def _groups():
    mk = lambda name, fam: (SimpleNamespace(name=name, family=fam), [])  # noqa: E731
    return [mk("nonlinear_stiffness", "stiffness"), mk("kinematic_error_harmonic", "theta_m:2"),
            mk("kinematic_error_harmonic", "theta_m:2:stiff"), mk("nonlinear_stiffness", "stiffness:5")]


def _run(trace, monkeypatch, new_sel=(0, 1, 2)):
    calls = []

    def fake_select(gram, base_idx, groups, opt, reshape=None, confirm=None, closed=(), carrier=None):
        calls.append(set(closed))
        return list(new_sel), [{"step": "add", "candidate": "x"}]

    monkeypatch.setattr(core, "select_groups", fake_select)
    statements, held = [], set()
    sel = core._reselect_without_heldout_drop(None, [], _groups(), core.Options(), [0, 1], 3, trace, {"backlash"},
                                              held, None, None, statements)
    return sel, calls, held, statements


def test_displacing_group_dropped_on_held_out_data_reselects_without_its_family(monkeypatch):
    trace = [{"step": "add", "candidate": "kinematic_error_harmonic[theta_m:2:stiff]"},
             {"step": "add", "candidate": "nonlinear_stiffness[stiffness:5]"},
             {"step": "drop (unidentified)", "candidate": "kinematic_error_harmonic[theta_m:2:stiff]"}]
    sel, calls, held, statements = _run(trace, monkeypatch)
    assert sel == [0, 1, 2]
    assert calls == [{"backlash", "stiffness:5"}]  # the shape-closed families stay closed, the dropped one joins
    assert held == {"stiffness:5"}
    rec = next(r for r in trace if r["step"] == "reselect (held-out drop)")
    assert rec["displaced"] == ["kinematic_error_harmonic[theta_m:2:stiff]"] and rec["closed"] == ["stiffness:5"]
    assert "displaced" in statements[-1]


def test_group_that_displaced_nothing_leaves_the_selection_alone(monkeypatch):
    # dropped earlier than the dropped group's entry, or no drop at all: nothing was displaced by it
    for trace in ([{"step": "drop", "candidate": "unknown[bias]"},
                   {"step": "add", "candidate": "nonlinear_stiffness[stiffness:5]"}],
                  [{"step": "add", "candidate": "nonlinear_stiffness[stiffness:5]"},
                   {"step": "stop", "candidate": "unknown[bias]"}],
                  []):
        n = len(trace)
        sel, calls, held, statements = _run(trace, monkeypatch)
        assert sel == [0, 1] and calls == [] and held == set() and statements == [] and len(trace) == n
