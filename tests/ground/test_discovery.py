"""Discovery closes the loop on data with exactly one (or two) undeclared effects; no false discovery."""

import json

import numpy as np
import pytest

from hd_ground.discovery.core import Options
from hd_ground.discovery.pipeline import run_discovery


def _run(tmp_path, missions, **kw):
    names = [f"bag{i}" for i in range(len(missions))]
    return run_discovery(names, tmp_path / "out", missions=missions, log=lambda s: None, plots=False, **kw)


def _pair(make_mission, effects, **kw):
    return [make_mission(0, effects=effects, **kw), make_mission(1, effects=effects, index=1, **kw)]


def _wrapped_diff(a, b):
    return abs((a - b + np.pi) % (2 * np.pi) - np.pi)


def test_clean_data_gives_no_effect_and_leaves_the_twin(tmp_path, make_mission):
    rep = _run(tmp_path, _pair(make_mission, {}))
    assert rep["effects"] == []
    assert rep["declared_after"] == rep["declared_before"]
    assert rep["twin_out"] is None and not (tmp_path / "out" / "twin").exists()
    assert rep["error_after"]["rmse"] == rep["error_before"]["rmse"]


# (effect spec, expected name, variable, order, {parameter: truth}, tolerance)
CASES = [
    ({"position_periodic_friction": (0.04, 2, 0.7)}, "position_periodic_friction", "theta_m", 2, {"F_2": 0.04, "phase_2": 0.7}),
    ({"position_periodic_torque": (0.04, 1, -0.4)}, "position_periodic_torque", "theta_m", 1, {"A_1": 0.04, "phase_1": -0.4}),
    ({"cogging_torque": (0.04, 12, 0.3)}, "cogging_torque", "theta_m", 12, {"A_12": 0.04, "phase_12": 0.3}),
    ({"stribeck_friction": (0.15, 4.0)}, "stribeck_friction", "omega_m", None, {"T_S_minus_T_C": 0.15, "omega_s": 4.0}),
    ({"load_dependent_friction": 0.002}, "load_dependent_friction", "Q_red", None, {"c_L": 0.002}),
]


@pytest.mark.parametrize("effects, name, variable, order, truth", CASES, ids=[c[1] for c in CASES])
def test_one_undeclared_effect_is_found_named_and_identified(tmp_path, make_mission, effects, name, variable, order, truth):
    rep = _run(tmp_path, _pair(make_mission, effects))
    assert len(rep["effects"]) >= 1
    e = rep["effects"][0]
    assert (e["name"], e["variable"], e["order"]) == (name, variable, order)
    for k, v in truth.items():
        if k.startswith("phase"):
            assert _wrapped_diff(e["parameters"][k], v) < 0.1, (k, e["parameters"][k], v)
        else:  # amplitudes within 10 %, Stribeck speed within 30 % (grid search)
            tol = 0.3 if k == "omega_s" else 0.1
            assert abs(e["parameters"][k] - v) <= tol * abs(v), (k, e["parameters"][k], v)
    assert rep["error_after"]["rmse"] <= 0.5 * rep["error_before"]["rmse"]
    assert name in rep["declared_after"] and name not in rep["declared_before"]
    cfg = json.loads((tmp_path / "out" / "twin" / "config.json").read_text())
    assert name in cfg["declared_effects"] and cfg["extra_terms"][0]["name"] == name


def test_pair_of_effects_both_found(tmp_path, make_mission):
    eff = {"position_periodic_friction": (0.04, 2, 0.7), "cogging_torque": (0.04, 12, 0.3)}
    rep = _run(tmp_path, _pair(make_mission, eff))
    found = {(e["name"], e["order"]) for e in rep["effects"]}
    assert {("position_periodic_friction", 2), ("cogging_torque", 12)} <= found
    assert rep["error_after"]["rmse"] <= 0.5 * rep["error_before"]["rmse"]


def test_effect_outside_the_catalog_is_reported_as_unknown(tmp_path, make_mission):
    # a direction-independent ripple at a non-integer order (e.g. a belt or a second gear stage)
    eff = {"position_periodic_torque": (0.04, 2.5, 0.2)}
    rep = _run(tmp_path, _pair(make_mission, eff))
    e = rep["effects"][0]
    assert e["name"] == "unknown" and e["variable"] == "theta_m" and abs(e["order"] - 2.5) < 0.05
    assert rep["error_after"]["rmse"] <= 0.5 * rep["error_before"]["rmse"]


def test_unknown_per_bag_angle_offset_is_estimated(tmp_path, make_mission):
    eff = {"position_periodic_friction": (0.03, 2, 0.7)}
    ms = [make_mission(0, effects=eff), make_mission(1, effects=eff, offset=1.3, index=1)]
    rep = _run(tmp_path, ms, opt=Options(angle_offset="estimate"))
    s = rep["signals"][0]
    assert _wrapped_diff(s["angle_offsets"]["bag1"], -1.3) < 0.05  # rotation that maps the logged angle back
    naive = s["comparisons"]["selected_terms_plain_lstsq_no_offset"]["rmse"]
    assert rep["error_after"]["rmse"] < 0.5 * naive


def test_constant_speed_one_direction_states_what_cannot_be_identified(tmp_path, make_mission):
    ms = _pair(make_mission, {"stribeck_friction": (0.08, 2.0)}, const_speed=True)
    rep = _run(tmp_path, ms)
    text = " ".join(rep["statements"])
    assert "one direction only" in text and "constant speed only" in text
    assert not any(e["name"] in ("stribeck_friction", "position_periodic_friction") for e in rep["effects"])


def test_too_little_data_is_refused_with_a_reason(tmp_path, make_mission):
    ms = _pair(make_mission, {"cogging_torque": (0.02, 12, 0.3)}, T=0.6)
    rep = _run(tmp_path, ms)
    assert rep["identifiable"] is False and rep["effects"] == []
    assert "too little data" in rep["statements"][0]


def test_declared_effect_from_twin_dir_is_not_rediscovered(tmp_path, make_mission):
    eff = {"position_periodic_friction": (0.03, 2, 0.7), "cogging_torque": (0.02, 12, 0.3)}
    ms = _pair(make_mission, eff)
    first = _run(tmp_path, ms)
    twin1 = tmp_path / "out" / "twin"
    rep2 = run_discovery(["bag0", "bag1"], tmp_path / "out2", missions=ms, twin_dir=str(twin1), log=lambda s: None,
                         plots=False)
    assert rep2["effects"] == []  # everything the data hold is now in the twin
    assert rep2["error_before"]["rmse"] <= 1.05 * first["error_after"]["rmse"]
