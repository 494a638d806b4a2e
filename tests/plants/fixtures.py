"""Session-scoped pytest fixtures giving bags of the independent plant (imported by ``tests/conftest.py``).

- ``plant2_case_bags(effect="clean", duration=None)``: one effect's case (4 missions: 3 fit, 1 held out);
  ``plant2_case_bags.signals(effect, duration=None)``: the simulated arrays only.
- ``plant2_fleet``: a small run-to-failure fleet with ``events.csv`` and ``fleet_truth.json``.
"""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def plant2_case_bags(tmp_path_factory):
    """Factory ``plant2_case_bags(effect="clean", duration=None) -> dict`` of the independent plant
    (tests/plants/ema2.py).

    One actuator, four contract bags of ``duration`` s each (default ``ema2.CASE_DURATION`` = 8 s), the
    same four missions for every effect (seeds 0..3), one undeclared effect (names:
    ``tests.plants.ema2.EFFECTS``). Keys: ``bags`` (4 paths), ``fit`` (first three), ``held_out`` (the
    fourth), ``truth`` (effect, parameters, signal it shows in), ``truth_path``,
    ``signals`` (simulated arrays incl. truth, for checks only). All effects are simulated in one batch on
    first use of a duration (about 1.2 s of one core per simulated second); each effect's bags are written
    when first asked for (about 0.1 s per simulated second and bag). ``plant2_case_bags.signals(effect)``
    gives the simulated arrays without writing bags.
    """
    from tests.plants import ema2

    return _Plant2Cases(tmp_path_factory.mktemp("plant2_cases"), ema2)


class _Plant2Cases:
    """``cases(effect, duration=None)`` -> the case dict (bags written on first ask);
    ``cases.signals(effect, duration=None)`` -> the simulated arrays only (no bag written)."""

    def __init__(self, root, ema2):
        self.root, self.ema2, self._sigs, self._cases = root, ema2, {}, {}

    def signals(self, effect: str = "clean", duration: float | None = None) -> list:
        if effect not in self.ema2.EFFECTS:
            raise ValueError(f"plant2: unknown effect {effect!r}; known: {', '.join(self.ema2.EFFECTS)}")
        d = float(duration or self.ema2.CASE_DURATION)
        if d not in self._sigs:
            self._sigs[d] = self.ema2.simulate_cases(duration=d)
        return self._sigs[d][effect]

    def __call__(self, effect: str = "clean", duration: float | None = None) -> dict:
        d = float(duration or self.ema2.CASE_DURATION)
        if (effect, d) not in self._cases:
            self._cases[effect, d] = self.ema2.write_case(self.root / f"{effect}_{d:g}s", effect, duration=d,
                                                          sigs=self.signals(effect, d))
        return self._cases[effect, d]


@pytest.fixture(scope="session")
def plant2_fleet(tmp_path_factory):
    """A small run-to-failure fleet of the independent plant: ``{"dir", "events", "truth"}``.

    4 units, at most 10 missions of 3 s each (nominal life 5 missions, unit scatter), inspections every
    third mission, 30 % of units planned for a removal while healthy (seed 3: three failures, one removal). ``dir/EMA2-Uxx/mission_000.mcap`` ... (missions flown only), ``dir/events.csv``
    (``actuator_id,mission_index,event,quantity,value``), ``dir/fleet_truth.json`` (true wear per mission,
    thresholds, failure missions: scoring only).
    """
    import csv

    from tests.plants import ema2

    out = tmp_path_factory.mktemp("plant2_fleet")
    truth = ema2.fleet(out, units=4, missions=10, duration=3.0, seed=3, life_missions=5.0, inspect_every=3,
                       remove_frac=0.3)
    with open(out / "events.csv") as f:
        events = list(csv.DictReader(f))
    return {"dir": out, "events": events, "truth": truth}
