"""A mission whose explicit integration diverges is re-integrated with a finer step; a plant that still cannot be
simulated ends that unit's life (what was simulated is kept) or leaves the unit out, and says so: no traceback, no
lost fleet truth."""

from __future__ import annotations

import json

import pytest

import hd_sim.plant as plant
from hd_sim.fleet import simulate_fleet, simulate_life
from hd_sim.params import sample_population


def _unit():
    p = sample_population(4, 5)[3]  # this draw diverges in its 4th inspection mission at the default 25 us step
    p["mission_hours"] = 2000.0
    return p


def test_a_diverging_mission_is_integrated_again_with_a_finer_step():
    rows = simulate_life(_unit(), 5, None, duration=2.0, seed=5, sim_internal_every=0, profiles=("inspection",))
    assert len(rows) == 5
    assert [r.get("n_sub") for r in rows] == [None, None, None, 80, None]  # default 40 at 1 kHz, halved once


def test_a_plant_that_cannot_be_simulated_ends_the_life_or_leaves_the_unit_out(tmp_path, monkeypatch, capsys):
    real = plant.simulate_mission

    def diverging_from(m0):
        def sm(*a, **kw):
            if kw["mission_index"] >= m0:
                raise FloatingPointError("plant diverged at sample 7 (t = 0.007 s)")
            return real(*a, **kw)
        return sm

    monkeypatch.setattr(plant, "simulate_mission", diverging_from(2))
    rows = simulate_life(_unit(), 5, tmp_path / "life", duration=1.0, seed=5, sim_internal_every=0)
    assert len(rows) == 2 and "plant diverged in mission 2" in rows[-1]["life_ended"]
    assert "n_sub tried: 40, 80, 160" in rows[-1]["life_ended"]
    assert len(list((tmp_path / "life").rglob("*.mcap"))) == 2  # the missions simulated are kept
    s = simulate_fleet(2, 4, tmp_path / "fleet", seed=5, duration=1.0, progress=False, sim_internal_every=0)
    assert all(a["life_ended"].startswith("plant diverged in mission 2") for a in s["actuators"])
    assert json.loads((tmp_path / "fleet" / "fleet_truth.json").read_text())["actuators"][0]["life_ended"]

    monkeypatch.setattr(plant, "simulate_mission", diverging_from(0))
    with pytest.raises(FloatingPointError, match="no actuator could be simulated"):
        simulate_fleet(2, 3, tmp_path / "none", seed=5, duration=1.0, progress=False, sim_internal_every=0)
    from hdphm.cli import main

    capsys.readouterr()
    assert main(["sim", "fleet", "--actuators", "1", "--missions", "2", "--duration", "1", "--seed", "5",
                 "--out", str(tmp_path / "cli")]) == 1  # a clean error, not a traceback
    assert "no actuator could be simulated" in capsys.readouterr().err
