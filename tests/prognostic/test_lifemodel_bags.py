"""The life model on bags: fit/prognose/metrics end to end on a tiny fleet, identical with /sim stripped."""

from __future__ import annotations

import json

import pytest

from hdphm.cli import main as hdphm
from tests.prognostic.stripsim import strip_fleet


@pytest.fixture(scope="module")
def fleets(small_fleet_dir, tmp_path_factory):
    stripped = tmp_path_factory.mktemp("nosim")
    assert strip_fleet(small_fleet_dir, stripped) > 0  # the fixture's bags do carry /sim topics
    ev = tmp_path_factory.mktemp("ev") / "events.csv"
    ids = sorted(p.name for p in small_fleet_dir.iterdir() if p.is_dir())
    # an operator's record: two units found failed at the start of mission 3 (they flew 0..2), one in service
    ev.write_text("actuator_id,mission_index,event,quantity,value\n"
                  f"{ids[0]},3,failure,,\n{ids[1]},3,failure,,\n{ids[2]},1,inspection,wear_depth,2e-6\n")
    return small_fleet_dir, stripped, ev, ids


def _run(fleet, ev, ids, out):
    assert hdphm(["prognostic", "fit", str(fleet), "--events", str(ev), "--out", str(out / "m.json"),
                  "--exposure", "load", "--path", "power"]) == 0  # plumbing test: the quick path family
    assert hdphm(["prognose", str(fleet / ids[2]), "--model", str(out / "m.json"), "--out", str(out / "p"),
                  "--samples", "200", "--no-plots"]) == 0
    return json.loads((out / "m.json").read_text()), json.loads((out / "p" / "rul_history.json").read_text())


def test_fit_prognose_metrics_identical_without_sim(fleets, tmp_path):
    full, stripped, ev, ids = fleets
    m1, h1 = _run(full, ev, ids, tmp_path / "a")
    m2, h2 = _run(stripped, ev, ids, tmp_path / "b")
    assert m1["theta"] == m2["theta"] and m1["E_ref"] == m2["E_ref"]
    for k in ("rul_t", "p5", "p50", "p95", "rul_quantiles", "state_mean"):
        assert h1[k] == h2[k], k
    assert m1["fit_info"]["n_failures"] == 2 and m1["exposure"] == "load"
    assert h1["time_unit"] == "mission" and len(h1["rul_t"]) == 3
    assert "rul_hours" in h1["meta"] and len(h1["meta"]["rul_hours"]["p50"]) == 3
    # scoring: EOL = failure mission index (here a made-up 6 for the in-service unit)
    assert hdphm(["metrics", str(tmp_path / "b" / "p" / "rul_history.json"), "--truth", "6"]) == 0
    assert json.loads((tmp_path / "b" / "p" / "metrics.json").read_text())["n_predictions"] == 3
