"""Shared, session-scoped fixtures built on the plant simulator (kept quick: seconds, not minutes).

- ``make_mission_bag(path, effects_on=(), effects_off=(), preset="baseline", params=None,
  duration=3.0, seed=0, profile="inspection", wear_um=0.0, with_sim=True, **kw)`` writes
  one contract bag and returns ``(path, Mission, truth)``. ``effects_on`` switches
  single effects on top of the preset, ``params`` is ``{"NAME.KEY": value}``.
- ``small_fleet_dir``: 3 actuators x 3 missions of 3 s (nominal wear schedule
  accelerated so wear visibly grows), one folder per actuator + fleet_truth.json.
- ``sim_mission``: a 3 s realistic (default effects) mission in memory: (Mission, truth).
"""

from __future__ import annotations

import pytest


def _make_mission_bag(path, effects_on=(), effects_off=(), preset="baseline", params=None, duration=3.0, seed=0,
                      profile="inspection", wear_um=0.0, with_sim=True, **kw):
    from hd_sim import EffectSet, write_sim_mission

    eff = EffectSet.preset(preset).with_on(*effects_on).with_off(*effects_off)
    if params:
        eff = eff.with_params(**params)
    health = {"h_plus": wear_um * 1e-6, "h_minus": wear_um * 1e-6}
    return write_sim_mission(path, None, eff, profile, seed, with_sim=with_sim, duration=duration,
                             health=health, **kw)


@pytest.fixture(scope="session")
def make_mission_bag():
    """Factory: ``make_mission_bag(path, effects_on=("stribeck_friction",), ...) -> (path, Mission, truth)``."""
    return _make_mission_bag


@pytest.fixture(scope="session")
def small_fleet_dir(tmp_path_factory):
    """A few actuators x a few short missions as bags (wear accelerated so it grows visibly)."""
    from hd_sim.fleet import simulate_life
    from hd_sim.params import sample_population

    out = tmp_path_factory.mktemp("fleet")
    import json

    summary = []
    for p in sample_population(3, seed=7):
        p["mission_hours"] = 5.0e3  # ~5 um of wear per mission: missions differ visibly
        rows = simulate_life(p, 3, out, duration=3.0, seed=7, sim_internal_every=1)
        summary.append({"actuator_id": p["actuator_id"], "missions": rows})
    with open(out / "fleet_truth.json", "w") as f:
        json.dump({"actuators": summary}, f, default=float)
    return out


@pytest.fixture(scope="session")
def sim_mission():
    """A 3 s mission with the realistic default effects, in memory: (Mission, truth)."""
    from hd_sim import simulate_mission

    return simulate_mission(None, None, "inspection", 3, duration=3.0)


# --- plant2: the independently written EMA plant of tests/plants/ema2.py (issue 9) -----------------
@pytest.fixture(scope="session")
def plant2_case_bags(tmp_path_factory):
    """Factory ``plant2_case_bags(effect="clean") -> dict`` of the independent plant (tests/plants/ema2.py).

    One actuator, four 12 s contract bags (the same four missions for every effect, seeds 0..3), one
    undeclared effect (names: ``tests.plants.ema2.EFFECTS``). Keys: ``bags`` (4 paths), ``fit`` (first
    three), ``held_out`` (the fourth), ``truth`` (effect, parameters, signal it shows in), ``truth_path``,
    ``signals`` (simulated arrays incl. truth, for checks only). All effects are simulated in one batch on
    first use (about 15 s on one core); each effect's bags are written when first asked for (about 5 s).
    """
    from tests.plants import ema2

    root = tmp_path_factory.mktemp("plant2_cases")
    state: dict = {}

    def make(effect: str = "clean") -> dict:
        if effect not in ema2.EFFECTS:
            raise ValueError(f"plant2: unknown effect {effect!r}; known: {', '.join(ema2.EFFECTS)}")
        if "sigs" not in state:
            state["sigs"] = ema2.simulate_cases()
        if effect not in state:
            state[effect] = ema2.write_case(root / effect, effect, sigs=state["sigs"][effect])
        return state[effect]

    return make


@pytest.fixture(scope="session")
def plant2_fleet(tmp_path_factory):
    """A small run-to-failure fleet of the independent plant: ``{"dir", "events", "truth"}``.

    4 units, at most 10 missions of 3 s each (nominal life 5 missions, unit scatter), inspections every
    third mission. ``dir/EMA2-Uxx/mission_000.mcap`` ... (missions flown only), ``dir/events.csv``
    (``actuator_id,mission_index,event,quantity,value``), ``dir/fleet_truth.json`` (true wear per mission,
    thresholds, failure missions: scoring only).
    """
    import csv

    from tests.plants import ema2

    out = tmp_path_factory.mktemp("plant2_fleet")
    truth = ema2.fleet(out, units=4, missions=10, duration=3.0, seed=3, life_missions=5.0, inspect_every=3)
    with open(out / "events.csv") as f:
        events = list(csv.DictReader(f))
    return {"dir": out, "events": events, "truth": truth}
