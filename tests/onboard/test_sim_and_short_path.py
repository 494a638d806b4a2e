"""Onboard core on the real plant simulator (hd_sim), the per-sample short path, deferred windows, eval."""
import json

import numpy as np
import pytest

from tests.onboard.simfix import faulted_mission, sim_mission

from hd_onboard.batch import run_mission  # noqa: E402
from hd_onboard.core import OnboardCore  # noqa: E402
from hd_onboard.windows import window_row  # noqa: E402
from hd_onboard.detectors.levels import ERROR, OK, WARN  # noqa: E402
from hd_onboard.features import window_feature_fn  # noqa: E402

#: stated detection delay of a sudden grease loss (friction x4, lubrication_loss severity 3, hd_sim's
#: mid-mission fault hook, 50 ms ramp) with the physics stand-in twin. Measured over 8 sim missions
#: (actuator 1, onset 8 + 0.5 k s, seed 20 + k; `python -m tests.onboard.simfix --severity 3`):
#: delays 0.16-0.30 s in 6, 1.05 s in 1 (friction shows only while the output moves), 1 mission (seed 23) flagged at 7.6 s,
#: before the onset (a false alarm on its bit-identical healthy part). Severity 2: delays 0.29-2.48 s in 6,
#: 1 missed. (The former spliced construction gave 0.14-0.68 s in 5, 1.81 s in 1: the bound still holds.)
#: This mission (seed 3, onset 10 s) is flagged 0.20 s after the onset.
FAULT_DELAY_S = 2.0


def _arrays(m):
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    return stamps, V


@pytest.fixture(scope="module")
def healthy():
    return [sim_mission(a, s, duration=16.0) for a in (0, 1) for s in (0, 1)]


def test_healthy_sim_missions_no_flag(healthy):
    for m in healthy:
        r = run_mission(m)
        assert r["max_level"] == OK, (m.meta.actuator_id, r["events"][:3])
        assert r["core"].calibrated and all(t.source.startswith("self") for t in r["core"].thresholds.values())


def test_fault_injected_mid_mission_flags_within_delay():
    m = faulted_mission(10.0, seed=3, actuator=1, duration=16.0)
    r = run_mission(m)
    assert r["max_level"] >= WARN and r["onset_s"] is not None
    assert 10.0 <= r["onset_s"] < 10.0 + FAULT_DELAY_S, r["onset_s"]
    assert {"Q_red", "friction"} & set(r["events"][0][2].split(",")), r["events"][0]  # lubrication loss: output-torque residual or its friction monitor
    h = run_mission(sim_mission(1, 3, duration=16.0))  # the same mission without the fault
    assert h["max_level"] == OK


def test_short_path_equals_block_path_on_messy_sim_data():
    """push_one gives the block path's numbers, with NaN, a gap, a duplicate, Q_red missing for a while."""
    m = sim_mission(0, 5, duration=9.0)
    stamps, V = _arrays(m)
    V[3000:3004, 4] = np.nan  # NaN burst in tau_m
    V[4000:4600, 5] = np.nan  # Q_red not measured for 0.6 s
    keep = np.ones(len(V), bool)
    keep[6000:6040] = False  # 40 ms dropout: twin reset
    stamps, V = stamps[keep], V[keep]
    stamps[7000] = stamps[6999]  # duplicate stamp: dropped
    ff = window_feature_fn({}, m.meta.gear_ratio)
    a = OnboardCore(gear_ratio=m.meta.gear_ratio, feature_fn=ff)
    tabs, wins, events = [], [], []
    for i in range(0, len(stamps), 700):
        r = a.push(stamps[i:i + 700], V[i:i + 700])
        tabs.append(r.table)
        wins += r.windows
        events += r.events
    wins += a.flush()
    b = OnboardCore(gear_ratio=m.meta.gear_ratio, feature_fn=ff)
    b.defer_windows = True
    for s_, v_ in zip(stamps.tolist(), V.tolist()):
        b.push_one(s_, v_)
    b.flush()
    A, B = np.concatenate(tabs), b.take_rows()
    assert A.shape == B.shape and len(A) == len(stamps) - 1
    np.testing.assert_allclose(B, A, rtol=1e-9, atol=1e-9, equal_nan=True)
    wb = [window_row(j, ff) for j in b.take_window_jobs()]
    assert len(wb) == len(wins) == 9
    for x, y in zip(wins, wb):
        assert x.keys() == y.keys()
        np.testing.assert_allclose([y[k] for k in x], [x[k] for k in x], rtol=1e-9, atol=1e-12, equal_nan=True)
    assert b.health.n_nan == a.health.n_nan == 4 and b.health.n_dropped_order == 1 and b.health.n_resets == a.health.n_resets >= 1
    assert b.level == a.level and b.take_events() == events


def test_short_path_with_ground_thresholds_detects_fault():
    from hd_ground.thresholds import actuator_thresholds

    th = actuator_thresholds([run_mission(sim_mission(1, s, duration=12.0)) for s in (10, 11)])
    m = faulted_mission(8.0, seed=12, actuator=1, duration=12.0)
    stamps, V = _arrays(m)
    core = OnboardCore(gear_ratio=m.meta.gear_ratio, thresholds=th)
    levels = [core.push_one(s_, v_) for s_, v_ in zip(stamps.tolist(), V.tolist())]
    assert max(levels[:7900]) == OK
    ev = core.take_events()
    # ground lines from two whole missions are wider than a mission's own warm-up lines: here the
    # fault shows first on the twist channel, 2.05 s after onset (measured); stated bound: 4 s
    assert ev and 8.0 <= (ev[0][0] - m.t0_ns) * 1e-9 < 8.0 + 4.0


def test_onboard_eval_false_alarm_rate_on_healthy_bags(tmp_path, healthy):
    from hd_bag import write_mission
    from hd_ground.references import calibrate_actuator
    from hd_onboard.evaluate import cmd_eval, evaluate_bags

    d = tmp_path / "bags"
    d.mkdir()
    for k, m in enumerate(healthy):
        write_mission(str(d / f"m{k}.mcap"), m)
    s = evaluate_bags([d])
    assert s["n_missions"] == 4 and s["missions_warn_or_worse"] == 0 and s["false_alarm_rate_per_mission"] == 0.0
    assert all(0 < r["margin"]["Q_red"] < 1 for r in s["missions"])
    g = evaluate_bags([d], ground=1, calibrate=calibrate_actuator)  # 2 actuators x 2 missions: 1 calibrates, 1 is scored each
    assert g["n_missions"] == 2 and set(g["calibration"]) == {m.meta.actuator_id for m in healthy}
    assert all(r["threshold_source"]["Q_red"].startswith("ground") for r in g["missions"])
    with pytest.raises(ValueError, match="need more than"):
        evaluate_bags([d], ground=2, calibrate=calibrate_actuator)
    with pytest.raises(ValueError, match="no such bag"):
        evaluate_bags([tmp_path / "nope"])

    class A:
        paths, ground, model_dir, quiet, out = [str(d)], 0, "", True, str(tmp_path / "ev")

    assert cmd_eval(A) == 0
    assert json.loads((tmp_path / "ev" / "onboard_eval.json").read_text())["n_missions"] == 4
    assert (tmp_path / "ev" / "onboard_eval.png").stat().st_size > 1000
