"""Ground calibration of the onboard monitors (hd_ground.references) and its route through the twin state."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("hd_sim")

from hd_ground.references import calibrate_actuator  # noqa: E402
from hd_onboard.batch import run_mission  # noqa: E402
from hd_onboard.core import OnboardCore  # noqa: E402
from hd_onboard.detectors.ewma import ChannelThreshold  # noqa: E402
from hd_onboard.detectors.friction import FrictionReference, fit_friction_reference  # noqa: E402
from hd_onboard.detectors.stiffness import fit_stiffness_reference  # noqa: E402
from hd_twin.state import apply_update, initial_state  # noqa: E402
from tests.onboard.simfix import faulted_mission, sim_mission  # noqa: E402


def test_pooled_fits_take_one_offset_per_mission():
    """Three 'missions' with different encoder / sensor zeros: the pooled law is the per-mission law."""
    rng = np.random.default_rng(3)
    n = 3000
    Q = 800 * np.sin(np.linspace(0, 20, 3 * n)) + 50 * rng.standard_normal(3 * n)
    w = 30 * np.sin(np.linspace(0, 13, 3 * n))
    grp = np.repeat([0, 1, 2], n)
    off = np.array([0.0, 0.02, -0.05])[grp]  # rad: 25-250x the elastic twist
    tw = off + 2e-6 * Q + 1e-4 * np.tanh(w) + 1e-7 * rng.standard_normal(3 * n)
    r1 = fit_stiffness_reference(tw, Q, w, eps=1.0, group=grp)
    assert r1 is not None and r1.compliance == pytest.approx(2e-6, rel=0.02) and r1.b == pytest.approx(1e-4, rel=0.05)
    r0 = fit_stiffness_reference(tw, Q, w, eps=1.0)  # one offset for all: the offsets swamp the law
    assert r0 is None or abs(r0.compliance - 2e-6) > 0.1 * 2e-6
    rq = np.array([0.0, 300.0, -200.0])[grp] - 120.0 * np.tanh(w / 0.05) + 5 * rng.standard_normal(3 * n)
    f1 = fit_friction_reference(rq, w, 0.05, 100.0, group=grp)
    assert f1.b == pytest.approx(-120.0, abs=2.0)
    # without groups the one-intercept fit is the former one (same law on one mission)
    f0 = fit_friction_reference(rq[:n], w[:n], 0.05, 100.0)
    assert f0.b == pytest.approx(-120.0, abs=2.0) and f0.a == pytest.approx(0.0, abs=2.0)


def test_friction_reference_from_dict_names_the_problem():
    d = FrictionReference(1.0, -50.0, 0.05, 100.0, 1000, "ground").to_dict()
    assert FrictionReference.from_dict(d) == FrictionReference(1.0, -50.0, 0.05, 100.0, 1000, "ground")
    with pytest.raises(ValueError, match="here: missing key 'b'"):
        FrictionReference.from_dict({k: v for k, v in d.items() if k != "b"}, "here")
    with pytest.raises(ValueError, match="scale"):
        FrictionReference.from_dict({**d, "scale": 0.0})
    with pytest.raises(ValueError, match="finite"):
        FrictionReference.from_dict({**d, "b": math.nan})
    with pytest.raises(ValueError, match="numbers"):
        FrictionReference.from_dict({**d, "a": "x"})


@pytest.fixture(scope="module")
def calibration():
    """Unit 2 of population 7: two healthy archived missions (seeds never used by the fault missions below)."""
    ms = [sim_mission(2, 1100 + j, duration=12.0, mission_index=j) for j in range(2)]
    return calibrate_actuator(ms)


def _core(cal, m, refs=True):
    th = {c: ChannelThreshold.from_dict(v, "test") for c, v in cal["thresholds"].items()}
    core = OnboardCore(gear_ratio=m.meta.gear_ratio, thresholds=th)
    if refs:
        core.set_stiffness_reference(cal["references"]["stiffness"])
        core.set_friction_reference(cal["references"]["friction"])
    return core


def test_ground_references_see_a_loss_present_from_mission_start(calibration):
    cal = calibration
    assert set(cal["references"]) == {"stiffness", "friction"} and set(cal["thresholds"]) == {"Q_red", "twist"}
    st = cal["references"]["stiffness"]
    assert st["source"] == "ground" and st["n"] >= 20000 and st["compliance"] != 0
    assert cal["references"]["friction"]["source"] == "ground"
    # lines with the onboard config's minimum (h_warn 5), not thresholds.py's older default 3
    assert all(v["h_warn"] >= 5.0 for v in cal["thresholds"].values())
    # 70 % flexspline stiffness loss from the first sample: the warm-up learns it as healthy ...
    m = faulted_mission(0.0, "flexspline_stiffness_loss", 0.7, actuator=2, seed=40, duration=12.0)
    self_cal = run_mission(m)
    assert self_cal["core"].stiffness_status()["reference"] == "mission warm-up"
    assert not any("stiffness" in e[2] for e in self_cal["events"])
    # ... the ground's healthy law does not
    g = run_mission(m, _core(cal, m))
    s = g["core"].stiffness_status()
    assert s["reference"] == "ground" and s["loss"] > 0.15
    assert g["core"].friction_status()["reference"] == "ground"
    ev = [e for e in g["events"] if "stiffness" in e[2]]
    assert ev and (ev[0][0] - m.t0_ns) * 1e-9 < 10.0
    # a healthy mission of the same unit (not in the calibration): no flag with the ground's lines + references
    h = sim_mission(2, 41, duration=12.0)
    rh = run_mission(h, _core(cal, h))
    assert rh["max_level"] == 0, rh["events"]
    assert np.nanmax(np.abs(rh["table"][:, 8])) < 0.15


def test_ground_reference_applied_mid_mission_restarts_the_monitor(calibration):
    m = sim_mission(2, 42, duration=16.0)
    core = OnboardCore(gear_ratio=m.meta.gear_ratio)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    st = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    core.push(st[:10000], V[:10000])
    assert core.stiffness_status()["reference"] == "mission warm-up"
    core.set_stiffness_reference(calibration["references"]["stiffness"])
    core.set_friction_reference(FrictionReference.from_dict(calibration["references"]["friction"]))
    assert core.stiffness.n_eval == 0 and core.stiffness_status()["reference"] == "ground"
    core.push(st[10000:], V[10000:])
    assert core.stiffness.n_eval > 0 and core.friction_status()["reference"] == "ground" and core.level == 0
    # the next mission keeps the ground's references
    core.reset_mission()
    assert core.stiffness_status()["reference"] == "ground" and core.friction_status()["reference"] == "ground"
    with pytest.raises(ValueError, match="onboard friction reference"):
        core.set_friction_reference({"a": 0.0})


def test_twin_state_carries_references(calibration):
    st0 = initial_state()
    assert st0["references"] == {}
    old = apply_update(st0, {"thresholds": {"EMA-0002": calibration["thresholds"]}, "updated_by": "ground"})
    assert old["references"] == {}  # an old payload (no references) still loads
    s1 = apply_update(old, {"references": {"EMA-0002": calibration["references"]}})
    assert s1["references"]["EMA-0002"]["stiffness"]["source"] == "ground"
    s2 = apply_update(s1, {"references": {"EMA-0003": {"friction": calibration["references"]["friction"]}}})
    assert set(s2["references"]) == {"EMA-0002", "EMA-0003"}  # merged per actuator
    bad = {k: v for k, v in calibration["references"]["stiffness"].items() if k != "q1"}
    with pytest.raises(ValueError, match=r"references\[EMA-0002\]\[stiffness\]: missing key 'q1'"):
        apply_update(s2, {"references": {"EMA-0002": {"stiffness": bad}}})
    with pytest.raises(ValueError, match="unknown monitor"):
        apply_update(s2, {"references": {"EMA-0002": {"backlash": {}}}})
    # a state written before this field existed: the onboard parser takes it
    from hd_twin.state import parse_references

    assert parse_references({}, "t") == {}
    assert set(parse_references(s2["references"], "t")["EMA-0002"]) == {"stiffness", "friction"}
