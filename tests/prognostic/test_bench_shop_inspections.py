"""bench/bench_prognostics.py's overhaul-shop emulation (scoring side): the quantity read from the simulator's truth,
the inspection schedule, and the events file it goes into (read back by the life model's reader)."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from hd_prognostic.lifemodel import UnitEvents, read_events, write_events

_BENCH = Path(__file__).resolve().parents[2] / "bench" / "bench_prognostics.py"
_spec = importlib.util.spec_from_file_location("bench_prognostics_for_tests", _BENCH)
bp = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bp)

P = {"delta_0": 2e-6, "alpha_p": math.radians(25.0), "r_m": 0.08}


def _truth():
    ms = [{"mission_index": k, "h_plus": 1e-6 * k, "h_minus": 1e-6 * k} for k in range(0, 41)]
    return {"actuators": [{"actuator_id": "A", "params": P, "eol_mission": 37, "missions": ms},
                          {"actuator_id": "B", "params": P, "eol_mission": None, "missions": ms[:24]}]}


def test_shop_values_known_answer():
    m = {"h_plus": 41e-6, "h_minus": 39e-6}
    assert bp.shop_value(P, m, "wear_depth") == pytest.approx(40e-6)
    # backlash once the preload is worn through: (80 - 4) um / cos 25 deg at r_m 80 mm = 1.048e-3 rad (3.6 arcmin)
    assert bp.shop_value(P, m, "lost_motion") == pytest.approx(76e-6 / math.cos(math.radians(25.0)) / 0.08)
    assert bp.shop_value(P, {"h_plus": 1e-6, "h_minus": 0.5e-6}, "lost_motion") == 0.0  # preload not yet consumed
    with pytest.raises(ValueError, match="stiffness"):
        bp.shop_value(P, m, "stiffness")


def test_schedule_noise_and_events_file(tmp_path):
    ev = {"A": UnitEvents(failure=37.0)}
    out = bp.shop_inspections(_truth(), ev, 10, "wear_depth", 0.0, at_failure=True)
    # failed unit: every 10 missions before its failure, and at its teardown; unit in service: up to its last mission
    assert [x[0] for x in out["A"].inspections] == [10.0, 20.0, 30.0, 37.0]
    assert [x[0] for x in out["B"].inspections] == [10.0, 20.0]
    assert out["A"].failure == 37.0 and out["B"].failure is None
    assert [x[2] for x in out["A"].inspections] == pytest.approx([10e-6, 20e-6, 30e-6, 37e-6])  # noise 0: the truth
    noisy = bp.shop_inspections(_truth(), ev, 1, "wear_depth", None)  # default gauge sd: 1 um
    err = np.array([(v - 1e-6 * t) / 1e-6 for t, _, v in noisy["A"].inspections])  # in um; wear = t um
    assert 0.6 < float(np.std(err)) < 1.5 and abs(float(np.mean(err))) < 0.5
    assert noisy["A"].inspections == bp.shop_inspections(_truth(), ev, 1, "wear_depth", None)["A"].inspections
    write_events(tmp_path / "ev.csv", out)
    back = read_events(tmp_path / "ev.csv")
    assert back["A"].inspections == out["A"].inspections and back["A"].failure == 37.0
