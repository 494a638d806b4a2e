"""The failure-time likelihood follows the failure *definition* (``lifemodel.failure_at_rule``), never a score.

``crossing`` when failure is defined as the recorded HI reaching a known level and the records show it: every
failed unit has a record at its failure time, the first at or past the level; ``interval`` (found failed at t_f)
otherwise. ``LifeModel.fit(failure_at="auto")``, ``hdphm prognostic fit`` (its default) and the bench use it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hd_prognostic.lifemodel import LifeModel, UnitEvents, UnitHistory, attach_events, failure_at_rule
from tests.prognostic.lifesynth import MEASURED

LEVEL = 1.6


def _cell(name: str, fade: float, n_after: int = 3, level: float = LEVEL) -> tuple[UnitHistory, float]:
    """A capacity-like HI falling linearly from 2.0 by ``fade`` per cycle (noise-free, so the crossing cycle is
    known); its failure = the first cycle at or below ``level``; ``n_after`` records after that cycle."""
    k = int(np.ceil((2.0 - level) / fade - 1e-9))
    t = np.arange(0.0, k + 1 + n_after)
    return UnitHistory(name, t, 2.0 - fade * t, t.copy()), float(k)


def _fleet(fades=(0.004, 0.005, 0.006, 0.0045), **kw):
    units, ev = [], {}
    for i, f in enumerate(fades):
        u, tf = _cell(f"B{i}", f, **kw)
        units.append(u)
        ev[u.unit] = UnitEvents(failure=tf)
    attach_events(units, ev)
    return units


def test_crossing_when_records_run_through_a_defined_level():
    units = _fleet()
    assert all(u.failure_record is not None and u.failure_record[0] == u.events.failure for u in units)
    assert all(u.t[-1] < u.events.failure for u in units)  # the records at and after the failure are dropped
    got, why = failure_at_rule(units, LEVEL)
    assert got == "crossing" and "4 failures" in why
    # the same records without a defined level: the failures are events, interval
    assert failure_at_rule(units, None)[0] == "interval"
    # increasing HI (crack length): reaching = passing upwards
    up = _fleet()
    for u in up:
        u.y = 4.0 - u.y
        u.failure_record = (u.failure_record[0], 4.0 - u.failure_record[1])
    assert failure_at_rule(up, 4.0 - LEVEL)[0] == "crossing"
    # censored units do not enter
    units[0].events = UnitEvents(removal=float(units[0].t[-1]))
    assert failure_at_rule(units, LEVEL)[0] == "crossing"


def test_interval_when_the_records_do_not_show_the_crossing():
    units = _fleet(n_after=0)
    # records stopping before the failure (found failed at t_f, nothing measured there)
    stop = _fleet()
    for u in stop:
        u.failure_record = None
    got, why = failure_at_rule(stop, LEVEL)
    assert got == "interval" and "no health-indicator record at its failure time" in why
    # a failure at a time the HI had not reached the level (the failure was something else)
    got, why = failure_at_rule(units, LEVEL - 0.05)
    assert got == "interval" and "has not reached" in why
    # a level some record before the failure had already reached
    got, why = failure_at_rule(units, LEVEL + 0.05)
    assert got == "interval" and "already reached" in why
    # a record at the failure time is needed, not a later one
    late = _fleet()
    late[1].failure_record = (late[1].failure_record[0] + 1.0, late[1].failure_record[1])
    assert failure_at_rule(late, LEVEL)[0] == "interval"


def test_fit_auto_follows_the_rule_and_says_why():
    units = _fleet(fades=(0.004, 0.005, 0.006, 0.0045, 0.0055))
    rng = np.random.default_rng(0)
    for u in units:  # measurement noise on the records (the crossing cycles stay as defined above)
        u.y = u.y + rng.normal(0.0, 0.002, len(u.y))
        keep = u.y > LEVEL
        u.t, u.y, u.E = u.t[keep], u.y[keep], u.E[keep]
    m = LifeModel.fit(units, path="power", threshold="auto", failure_level=LEVEL, failure_at="auto", n_draws=0,
                      maxiter=150)
    assert m.fit_info["failure_at"] == "crossing" and m.threshold == "observable"
    assert m.fit_info["failure_at_rule"].startswith("all 5 failures")
    iv = LifeModel.fit(units, path="power", threshold="auto", failure_at="auto", n_draws=0, maxiter=150)
    assert "failure_at" not in iv.fit_info and iv.fit_info["failure_at_rule"].startswith("no failure level")
    # asked for the latent threshold: the crossing density is not defined there, interval with the reason
    lat = LifeModel.fit(units, path="power", threshold="latent", failure_level=LEVEL, failure_at="auto", n_draws=0,
                        maxiter=150)
    assert "failure_at" not in lat.fit_info and "latent threshold" in lat.fit_info["failure_at_rule"]
    with pytest.raises(ValueError, match="failure_at"):
        LifeModel.fit(units, failure_at="sometimes")


needs_data = pytest.mark.skipif(not (MEASURED / "nasa_battery").is_dir() or not (MEASURED / "virkler").is_dir(),
                                reason="measured data folder not found (set HDPHM_MEASURED_DATA)")


@needs_data
def test_nasa_and_virkler_exports_are_recorded_crossings(tmp_path):
    """Both failure definitions are a measured level reached (1.6 Ah, 49.8 mm) and both exports run through it;
    the CLI fit (its default --failure-at auto) picks the crossing likelihood from that alone."""
    from hd_prognostic.lifemodel import read_events, read_hi_csv
    from hd_prognostic.realdata import RATED_AH, VIRKLER_LENGTHS_MM, battery_records, virkler_records
    from hdphm.cli import main as hdphm

    for (hi, ev), lvl in ((battery_records(MEASURED / "nasa_battery", tmp_path / "n"), 0.8 * RATED_AH),
                          (virkler_records(MEASURED / "virkler", tmp_path / "v"), VIRKLER_LENGTHS_MM[-1] * 1e-3)):
        units = read_hi_csv(hi)
        attach_events(units, read_events(ev))
        assert failure_at_rule(units, lvl)[0] == "crossing"
        # leave-one-out folds see the same definition
        assert {failure_at_rule(units[:i] + units[i + 1:], lvl)[0] for i in range(min(len(units), 4))} == {"crossing"}
    out = tmp_path / "m.json"
    assert hdphm(["prognostic", "fit", str(tmp_path / "n" / "battery_hi.csv"), "--events",
                  str(tmp_path / "n" / "battery_events.csv"), "--out", str(out), "--failure-level", str(0.8 * RATED_AH),
                  "--path", "power", "--draws", "0"]) == 0
    fi = json.loads(out.read_text())["fit_info"]
    assert fi["failure_at"] == "crossing" and fi["failure_at_rule"].startswith("all 3 failures")
