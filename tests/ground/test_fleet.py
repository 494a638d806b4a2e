"""Fleet store, tasks and classifier without a cluster (fast)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("duckdb")
pytest.importorskip("pyarrow")


@pytest.fixture(scope="module")
def fleet_bags(small_fleet_dir):
    return sorted(str(p) for p in small_fleet_dir.rglob("*.mcap"))


def test_mission_task_commits_once_and_is_queryable(fleet_bags, tmp_path):
    from hd_ground.fleet.store import FleetStore
    from hd_ground.fleet.tasks import FleetOptions, calibrate_task, mission_task

    opts = FleetOptions(healthy_missions=1, onboard={"warmup_s": 1.0})
    aid_bags = [b for b in fleet_bags if "EMA-0000" in b]
    cal = calibrate_task(aid_bags[:1], opts)
    assert set(cal["thresholds"]) == {"Q_red", "twist"} and "estimates" in cal["recalibration"]
    r = mission_task(aid_bags[1], str(tmp_path), cal, opts)
    assert r["stored"] and r["mission_index"] == 1
    again = mission_task(aid_bags[1], str(tmp_path), cal, opts)  # a retried task: nothing written twice
    assert not again["stored"]
    st = FleetStore(tmp_path)
    assert st.done_missions() == {"EMA-0000": {1}}
    cols, rows = st.query("SELECT count(*), min(samples), max(Q_red_rms) FROM missions JOIN residual_stats "
                          "USING (actuator_id, mission_index)")
    assert rows[0][0] == 1 and rows[0][1] == 3000 and rows[0][2] > 0
    cols, rows = st.query("SELECT HF_MTW_IF, W_load FROM features")
    assert np.isfinite(rows[0][0]) and rows[0][1] > 0
    assert not list((tmp_path / "_tmp").iterdir())  # the temporary folder was moved, not copied
    with pytest.raises(ValueError, match="SQL error"):
        st.query("SELECT nope FROM missions")


def test_fleet_cli_status_and_query(fleet_bags, tmp_path, capsys):
    from hd_ground.fleet.tasks import FleetOptions, calibrate_task, mission_task
    from hdphm.cli import main

    opts = FleetOptions(healthy_missions=1, onboard={"warmup_s": 1.0})
    bags = [b for b in fleet_bags if "EMA-0001" in b]
    cal = calibrate_task(bags[:1], opts)
    for b in bags:
        mission_task(b, str(tmp_path), cal, opts)
    assert main(["fleet", "query", "--store", str(tmp_path), "--format", "csv",
                 "SELECT actuator_id, count(*) AS n FROM missions GROUP BY 1"]) == 0
    assert capsys.readouterr().out.splitlines() == ["actuator_id,n", f"EMA-0001,{len(bags)}"]
    assert main(["fleet", "status", "--store", str(tmp_path)]) == 0  # no RUL / classes yet: shown as '-'
    line = capsys.readouterr().out.splitlines()[1]
    assert line.split()[:3] == ["EMA-0001", str(len(bags)), str(len(bags) - 1)]
    assert main(["fleet", "status", "--store", str(tmp_path / "nothing")]) == 1  # clear error, not a traceback
    assert "not a fleet store" in capsys.readouterr().err


def test_calibration_skips_an_unreadable_reference_bag(fleet_bags, tmp_path):
    from hd_ground.fleet.tasks import FleetOptions, calibrate_task

    bad = tmp_path / "broken.mcap"
    bad.write_bytes(b"not an mcap file at all")
    opts = FleetOptions(healthy_missions=2, onboard={"warmup_s": 1.0})
    cal = calibrate_task([str(bad), [b for b in fleet_bags if "EMA-0002" in b][0]], opts)
    assert cal["reference_missions"] == [0] and "Q_red" in cal["thresholds"]
    assert len(cal["skipped"]) == 1 and "broken.mcap" in cal["skipped"][0]
    none = calibrate_task([str(bad)], opts)
    assert "no readable reference bag" in none["error"] and none["thresholds"] == {}


def test_write_mission_is_atomic_against_a_concurrent_duplicate(tmp_path):
    from hd_ground.fleet.store import FleetStore

    st = FleetStore(tmp_path)
    rows = {"missions": [{"actuator_id": "a/b", "mission_index": 3, "x": 1.0}], "features": [{"actuator_id": "a/b",
            "mission_index": 3}], "residual_stats": [{"actuator_id": "a/b", "mission_index": 3}], "events": []}
    assert st.write_mission("a/b", 3, rows)
    rows["missions"][0]["x"] = 2.0
    assert not st.write_mission("a/b", 3, rows)  # the first commit wins, the second leaves nothing behind
    assert st.query("SELECT x FROM missions")[1] == [(1.0,)]
    assert st.done_missions() == {"a/b": {3}}  # ids with '/' are escaped in folder names


def test_gaussian_classifier_held_out_and_unknown():
    from hd_ground.fleet.classify import CLASSES, FEATURES, GaussianFaultClassifier, NearestCentroid

    rng = np.random.default_rng(0)
    d = len(FEATURES)
    centres = {c: 3.0 * np.eye(d)[i] for i, c in enumerate(CLASSES)}

    def draw(n):
        X = np.concatenate([centres[c] + rng.standard_normal((n, d)) for c in CLASSES])
        return X, [c for c in CLASSES for _ in range(n)]

    Xtr, ytr = draw(40)
    Xte, yte = draw(40)
    m = GaussianFaultClassifier().fit(Xtr, ytr)
    acc = np.mean(np.array(m.predict(Xte)) == np.array(yte))
    base = np.mean(np.array(NearestCentroid().fit(Xtr, ytr).predict(Xte)) == np.array(yte))
    assert acc > 0.85 and base > 0.8
    p = m.predict_proba(Xte)
    assert np.allclose(p.sum(axis=1), 1.0)
    far = np.full(d, 40.0)
    assert m.predict(far) == ["unknown"]
    x = Xte[0].copy()
    x[2] = np.nan  # a monitor that did not evaluate: marginalised, not an error
    assert np.isfinite(m.predict_proba(x)).all()
    m2 = GaussianFaultClassifier.from_json(m.to_json())
    assert np.allclose(m2.predict_proba(Xte[:5]), p[:5])
    with pytest.raises(ValueError, match="retrain"):
        GaussianFaultClassifier.from_json({**m.to_json(), "features": ["x"]})


def test_train_classifier_cli_chooses_the_covariance_across_plant_types(fleet_bags, tmp_path, capsys):
    """`hdphm fleet train-classifier` with a plant column: the covariance chosen by leave one plant out (folds whose
    other plants cannot be fitted are skipped, not an error); a plant column filled for some actuators only is
    refused by name."""
    import json

    from hd_ground.fleet.tasks import FleetOptions, calibrate_task, mission_task
    from hdphm.cli import main

    opts = FleetOptions(healthy_missions=1, onboard={"warmup_s": 1.0})
    store = tmp_path / "store"
    ids = sorted({b.split("/")[-2] for b in fleet_bags if "EMA-" in b.split("/")[-2]})[:3]
    for aid in ids:
        bags = [b for b in fleet_bags if f"/{aid}/" in b]
        cal = calibrate_task(bags[:1], opts)
        for b in bags:
            mission_task(b, str(store), cal, opts)
    plant = {ids[0]: "P1", ids[1]: "P1", ids[2]: "P2"}
    lab = {(ids[0], 1): "healthy", (ids[0], 2): "healthy", (ids[1], 1): "tooth_wear", (ids[1], 2): "tooth_wear",
           (ids[2], 1): "healthy", (ids[2], 2): "tooth_wear"}
    rows = ["actuator_id,mission_index,label,plant"] + [f"{a},{k},{v},{plant[a]}" for (a, k), v in lab.items()]
    (tmp_path / "labels.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "clf.json"
    assert main(["fleet", "train-classifier", "--store", str(store), "--labels", str(tmp_path / "labels.csv"),
                 "--out", str(out), "--healthy-missions", "1"]) == 0
    assert "leave-one-plant-out over P1, P2" in capsys.readouterr().out
    ch = json.loads(out.read_text())["info"]["covariance_choice"]
    assert ch["plants"] == ["P1", "P2"] and set(ch["per_plant"]["pooled"]) == {"P2"}  # P2 alone cannot be fitted
    for bad, msg in (([r.rsplit(",", 1)[0] + "," if r.startswith(ids[2]) else r for r in rows],
                      "plant column is empty for some actuators"),  # one actuator without its plant type
                     (rows[:-1] + [rows[-1].rsplit(",", 1)[0] + ",P1"], "one plant type per actuator")):
        (tmp_path / "labels.csv").write_text("\n".join(bad) + "\n")
        assert main(["fleet", "train-classifier", "--store", str(store), "--labels", str(tmp_path / "labels.csv"),
                     "--out", str(out), "--healthy-missions", "1"]) == 1
        assert msg in capsys.readouterr().err
