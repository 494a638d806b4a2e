"""Shared, session-scoped fixtures built on the plant simulator (kept quick: seconds, not minutes).

- ``make_mission_bag(path, effects_on=(), effects_off=(), preset="baseline", params=None,
  duration=3.0, seed=0, profile="inspection", wear_um=0.0, with_sim=True, **kw)`` writes
  one contract bag and returns ``(path, Mission, truth)``. ``effects_on`` switches
  single effects on top of the preset, ``params`` is ``{"NAME.KEY": value}``.
- ``small_fleet_dir``: 3 actuators x 3 missions of 3 s (nominal wear schedule
  accelerated so wear visibly grows), one folder per actuator + fleet_truth.json.
- ``sim_mission``: a 3 s realistic (default effects) mission in memory: (Mission, truth).
- ``family_names``, ``family_case_bags(family, effect=None, ...)`` -> FamilyCase, ``family_fleet(family, ...)``
  -> Path: the structurally different hd_sim plant families (docs/FAMILIES.md), built once per session.
- ``plant_world`` (parametrised over ``PLANT_WORLD``: three families + plant2): a ``World`` with
  ``case(effect=None)`` and ``fleet()``, one interface for every world.
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


# ---------------------------------------------------------------------------------------------
# Plant families (hd_sim.families, issue 9): structurally different plants, built once per run.
# ---------------------------------------------------------------------------------------------
#: The structurally different families every estimator test should also pass on (not ``default``).
FAMILY_WORLD = ("smooth-cubic", "deadzone-lugre", "hysteretic-robot")


class FamilyCase:
    """Short missions of one actuator of a family: ``bags`` (paths), ``missions``, ``truths``, ``units``."""

    def __init__(self, family, effect, bags, missions, truths, units):
        self.family, self.effect = family, effect
        self.bags, self.missions, self.truths, self.units = bags, missions, truths, units

    def __repr__(self):
        return f"FamilyCase({self.family!r}, effect={self.effect!r}, {len(self.bags)} bags)"


def _family_case(root, family, effect=None, n_missions=4, duration=4.0, seed=0, preset="baseline"):
    from hd_sim.families import write_family_case

    out = root / f"{family}__{effect or 'clean'}__{n_missions}x{duration:g}s_s{seed}"
    r = write_family_case(out, family, effect, n_missions=n_missions, duration=duration, seed=seed, preset=preset)
    return FamilyCase(family, effect, r["bags"], r["missions"], r["truths"], [r["unit"]])


@pytest.fixture(scope="session")
def family_names():
    """Names of the structurally different plant families (``FAMILY_WORLD``)."""
    return FAMILY_WORLD


@pytest.fixture(scope="session")
def family_case_bags(tmp_path_factory):
    """Factory ``family_case_bags(family, effect=None, n_missions=4, duration=4.0, seed=0, preset="baseline")
    -> FamilyCase``: one actuator of the family (its laws, gear ratio, sensors, log rate drawn, seeded) on
    top of the preset, ``effect`` (a registry effect name, the undeclared one) switched on, ``n_missions``
    missions cycling the family's test profiles, written as contract bags with ``/sim`` truth. Cached per
    session: the same arguments return the same object."""
    root = tmp_path_factory.mktemp("family_cases")
    cache = {}

    def make(family, effect=None, n_missions=4, duration=4.0, seed=0, preset="baseline"):
        key = (family, effect, int(n_missions), float(duration), int(seed), preset)
        if key not in cache:
            cache[key] = _family_case(root, *key)
        return cache[key]

    return make


def _family_fleet(root, family, n_actuators=3, n_missions=12, duration=2.0, seed=0, mission_hours=1.2e4):
    from hd_sim.fleet import simulate_fleet

    out = root / f"{family}_{n_actuators}x{n_missions}_s{seed}"
    s = simulate_fleet(n_actuators, n_missions, out, seed=seed, duration=duration, progress=False, family=family,
                       sim_internal_every=0, overrides={"mission_hours": mission_hours})
    write_failure_events(s, out / "events.csv")
    return out


def write_failure_events(summary, path):
    """``events.csv`` (actuator_id,mission_index,event,quantity,value) of an hd_sim fleet: one ``failure`` row per
    unit at its EOL mission (found failed at the start of it), as an operator's fleet records it."""
    import csv

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["actuator_id", "mission_index", "event", "quantity", "value"])
        for a in summary["actuators"]:
            if a["eol_mission"] is not None:
                w.writerow([a["actuator_id"], a["eol_mission"], "failure", "", ""])


@pytest.fixture(scope="session")
def family_fleet(tmp_path_factory):
    """Factory ``family_fleet(family, n_actuators=3, n_missions=12, duration=2.0, seed=0, mission_hours=1.2e4)
    -> Path``: a small run-to-failure fleet of the family (default realistic effects under the family's laws;
    wear accelerated so units fail within ~12 missions), ``DIR/<actuator>/*.mcap`` + ``fleet_truth.json``
    (per unit: ``family`` draws and laws, health per mission, ``eol_mission``) + ``events.csv`` (failures).
    Cached per session."""
    root = tmp_path_factory.mktemp("family_fleets")
    cache = {}

    def make(family, n_actuators=3, n_missions=12, duration=2.0, seed=0, mission_hours=1.2e4):
        key = (family, int(n_actuators), int(n_missions), float(duration), int(seed), float(mission_hours))
        if key not in cache:
            cache[key] = _family_fleet(root, *key)
        return cache[key]

    return make


# --- plant2: the independently written EMA plant of tests/plants/ema2.py (issue 9); fixtures live there
from tests.plants.fixtures import plant2_case_bags, plant2_fleet  # noqa: E402,F401


# --- every world at once: the hd_sim families + the independent plant2 ----------------------------------
#: Worlds an estimator test should pass on: three structurally different hd_sim families + plant2.
PLANT_WORLD = FAMILY_WORLD + ("plant2",)

#: Where an hd_sim effect shows first (as tests.plants.ema2.EFFECT_SIGNAL does for plant2).
_CATEGORY_SIGNAL = {"friction": "tau_m", "motor": "tau_m", "transmission": "Q_red", "load": "Q_red"}


class World:
    """One plant world with one interface, whatever wrote it (``plant_world`` fixture).

    ``name`` (family name or ``"plant2"``), ``kind`` (``"hd_sim"`` | ``"plant2"``),
    ``case(effect=None) -> dict`` with ``bags`` (4 paths), ``fit`` (first three), ``held_out`` (the fourth),
    ``truth`` (``plant``, ``effect``, ``signal`` it shows in); ``effect`` is a name of ``effects`` (the
    world's own vocabulary: hd_sim registry names, or ``tests.plants.ema2.EFFECTS``), None = clean.
    ``fleet() -> dict`` with ``dir`` (one folder per unit), ``events`` (rows of ``dir/events.csv``:
    failures; plant2 also inspections), ``truth`` (scoring only).
    """

    def __init__(self, name, request):
        self.name = name
        self.kind = "plant2" if name == "plant2" else "hd_sim"
        self._request = request

    @property
    def effects(self):
        if self.kind == "plant2":
            from tests.plants import ema2

            return tuple(e for e in ema2.EFFECTS if e != "clean")
        from hd_sim.effects import REGISTRY

        return tuple(n for n, e in REGISTRY.items() if not e.baseline and not e.slot and e.category in _CATEGORY_SIGNAL)

    def case(self, effect=None):
        if self.kind == "plant2":
            return self._request.getfixturevalue("plant2_case_bags")(effect or "clean")
        from hd_sim.effects import REGISTRY

        c = self._request.getfixturevalue("family_case_bags")(self.name, effect)
        sig = _CATEGORY_SIGNAL.get(REGISTRY[effect].category) if effect else None
        return {"bags": list(c.bags), "fit": list(c.bags[:-1]), "held_out": c.bags[-1], "case": c,
                "truth": {"plant": f"hd_sim family {self.name}", "effect": effect or "clean", "signal": sig}}

    def fleet(self):
        import csv
        import json

        if self.kind == "plant2":
            return self._request.getfixturevalue("plant2_fleet")
        d = self._request.getfixturevalue("family_fleet")(self.name)
        with open(d / "events.csv") as f:
            events = list(csv.DictReader(f))
        return {"dir": d, "events": events, "truth": json.loads((d / "fleet_truth.json").read_text())}

    def __repr__(self):
        return f"World({self.name!r})"


@pytest.fixture(scope="session", params=PLANT_WORLD)
def plant_world(request):
    """Parametrised over ``PLANT_WORLD`` (smooth-cubic, deadzone-lugre, hysteretic-robot, plant2): a
    :class:`World`; its bags and fleets are built on first use and cached for the session."""
    return World(request.param, request)
