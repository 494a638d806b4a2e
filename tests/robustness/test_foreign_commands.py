"""Every user-facing command on foreign-style bags: a correct result or one clear error (exit 1), no traceback.

Commands: ``train`` (tiny, 2 epochs, once), ``twin eval``, ``prognose``,
``prognostic features``, ``discover``, ``onboard eval``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hd_twin.data import edge_half_window
from hdphm.cli import main
from tests.robustness import foreign as FB

#: variants the 1 kHz twin must score without a note (same hardware, same rate family)
EVAL_CLEAN = ["plain", "rosbags", "lz4", "unchunked", "jitter", "dup_disorder", "extra_topics", "names_reversed",
              "sim_time"]


def _eval(capsys, model, *bags):
    rc = main(["twin", "eval", str(model), *map(str, bags)])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    return rc, (json.loads(cap.out) if rc == 0 else None), cap.err


@pytest.mark.parametrize("name", EVAL_CLEAN)
def test_twin_eval_scores_foreign_bags(foreign_twin, foreign_bags, name, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags[name])
    assert rc == 0 and met["n_missions"] == 1
    assert math.isfinite(met["rmse"]) and met["r2"] > 0.3, met
    assert "notes" not in met


@pytest.mark.parametrize("name,feature", [("no_temp", "temperature"), ("no_command", "e_ref")])
def test_twin_eval_without_a_sensor_says_so(foreign_twin, foreign_bags, name, feature, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags[name])
    assert rc == 0 and met["r2"] > 0.3
    assert any("not available" in s and feature in s for s in met["notes"]), met.get("notes")


@pytest.mark.parametrize("name", ["speed_rpm", "torque_sign"])
def test_twin_eval_repeats_suspect_data(foreign_twin, foreign_bags, name, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags[name])
    assert rc == 0 and any("suspect data" in s and FB.VARIANTS[name].match in s for s in met["notes"])


def test_twin_eval_across_a_dropout(foreign_twin, foreign_bags, capsys):
    """5 s mission with a 2 s hole: both segments scored (3000 samples less each segment's two edge
    half-windows, where the derivative is undefined: hd_twin.data.edge_samples), nothing bridged."""
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags["dropout"])
    m = edge_half_window(1e-3)
    assert rc == 0 and met["edge_excluded"] == 2 * 2 * m and met["n"] == 3000 - 4 * m and met["r2"] > 0.3
    # the 5 s inspection mission has larger steps than the 2 s training missions: an honest range note
    assert all("outside the training data" in s for s in met.get("notes", []))


def test_twin_eval_very_short_mission(foreign_twin, foreign_bags, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags["short"])  # 0.5 s: one LSTM warm-up, scored whole
    m = edge_half_window(1e-3)
    assert rc == 0 and met["n"] + met["edge_excluded"] == 500 and met["edge_excluded"] == 2 * m
    assert math.isfinite(met["rmse"]) and math.isfinite(met["r2"])


def test_twin_eval_10khz_bag_is_decimated(foreign_twin, foreign_bags, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags["fs10k"])
    # 6000 samples at 10 kHz -> 1 kHz (600), less the segment's two edge half-windows
    assert rc == 0 and met["n"] + met["edge_excluded"] == 600 and met["edge_excluded"] == 2 * edge_half_window(1e-3)
    assert math.isfinite(met["rmse"])


def test_twin_eval_refusals_are_one_line(foreign_twin, foreign_bags, capsys):
    for name, msg in (("fs100", "cannot be decimated"), ("no_torque", "no output torque sensor"),
                      ("theta_offset", "no common zero")):
        rc, _, err = _eval(capsys, foreign_twin, foreign_bags[name])
        assert rc == 1 and msg in err and str(foreign_bags[name]) in err, err


def test_twin_eval_notes_other_hardware_and_out_of_range_inputs(foreign_twin, foreign_bags, capsys):
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags["n160"], foreign_bags["no_torque"], foreign_bags["plain"])
    assert rc == 0 and met["n_missions"] == 2
    notes = " ".join(met["notes"])
    assert "N = 160 differs" in notes and "skipped" in notes and "no_torque" in notes
    rc, met, _ = _eval(capsys, foreign_twin, foreign_bags["theta_large"])  # flap 99 rad: far outside training
    assert rc == 0 and "theta_f" in met["out_of_range"] and met["out_of_range"]["theta_f"]["frac"] > 0.99
    assert any("outside the training data" in s for s in met["notes"])


def test_train_on_mixed_sample_rates_uses_the_lowest(foreign_bags, tmp_path, capsys):
    """100 Hz + 1 kHz + 10 kHz bags: one model rate every bag reaches by integer decimation (was the median)."""
    import shutil

    d = tmp_path / "bags"
    d.mkdir()
    for n in ("fs100", "plain", "fs10k"):
        shutil.copy(foreign_bags[n], d / f"{n}.mcap")
    rc = main(["train", "--preset", "tiny", "--bags", str(d), "--epochs", "1", "--threads", "1",
               "--out", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert rc == 0, err
    cfg = json.loads((tmp_path / "m" / "config.json").read_text())
    assert cfg["preprocessing"]["fs_model"] == pytest.approx(100.0, rel=1e-6)
    assert "model rate 100 Hz (the lowest)" in err


def test_train_refuses_a_folder_with_an_unusable_bag(foreign_bags, tmp_path, capsys):
    import shutil

    d = tmp_path / "bags"
    d.mkdir()
    shutil.copy(foreign_bags["plain"], d / "a.mcap")
    shutil.copy(foreign_bags["no_kt"], d / "b.mcap")
    rc = main(["train", "--preset", "tiny", "--bags", str(d), "--epochs", "1", "--out", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert rc == 1 and "b.mcap" in err and "torque_constant" in err and "Traceback" not in err


def test_prognose_reads_ros2_bag_folders_in_mission_order(foreign_actuator, tmp_path, capsys):
    d, paths = foreign_actuator
    out = tmp_path / "prog"
    assert main(["prognose", str(d), "--out", str(out), "--no-plots", "--particles", "500"]) == 0
    err = capsys.readouterr().err
    h = json.loads((out / "rul_history.json").read_text())
    assert h["unit"] == "FX-0100" and h["t"] == [float(k) for k in range(9)]
    z = np.array([np.nan if isinstance(v, str) else v for v in h["z"]], float)
    assert np.isnan(z[[2, 5, 6]]).all() and np.isfinite(z[[0, 1, 3, 4, 7, 8]]).all()  # gaps: predict-only
    assert "3 of 9 steps have no health observation" in err
    # mission-length note: 1.5 s missions vs the 20 s missions of the fitted population
    assert any("load-sliding work" in s for s in h["meta"]["notes"])
    q = np.array(h["rul_quantiles"], dtype=object)
    assert all(not (isinstance(v, float) and math.isnan(v)) and v != "nan" for row in q for v in row)
    assert len(paths) == 6


def test_prognose_skips_an_unreadable_bag_with_a_note(foreign_actuator, foreign_bags, tmp_path, capsys):
    import shutil

    d, _ = foreign_actuator
    d2 = tmp_path / "act"
    shutil.copytree(d, d2)
    shutil.copy(foreign_bags["zero_stamps"], d2 / "broken.mcap")
    assert main(["prognose", str(d2), "--out", str(tmp_path / "p"), "--no-plots", "--particles", "300"]) == 0
    h = json.loads((tmp_path / "p" / "rul_history.json").read_text())
    assert any("broken.mcap" in s and "stamp" in s for s in h["meta"]["skipped_bags"])


def test_prognose_when_mission_counters_disagree(tmp_path, capsys):
    """Hours running back along mission_index, and a tool that leaves every mission_index at 0."""
    plain = FB.replace(FB.VARIANTS["plain"], sim={"duration": 1.0})
    for k, (mi, oh) in enumerate([(0, 10.0), (1, 5.0), (2, 30.0), (3, 20.0)]):
        FB.write_variant(tmp_path / "hours", FB.replace(plain, name=f"m{k}"), seed=k, mission_index=mi,
                         operating_hours=oh, actuator_id="FX-H")
    for k, oh in enumerate([30.0, 10.0, 20.0]):
        FB.write_variant(tmp_path / "zero", FB.replace(plain, name=f"z{k}"), seed=k, mission_index=0,
                         operating_hours=oh, actuator_id="FX-Z")
    assert main(["prognose", str(tmp_path / "hours"), "--out", str(tmp_path / "ph"), "--no-plots",
                 "--particles", "300"]) == 0
    h = json.loads((tmp_path / "ph" / "rul_history.json").read_text())
    assert h["t"] == [0.0, 1.0, 2.0, 3.0] and h["meta"]["hours_per_mission"] == 25.0
    assert any("operating_hours decrease" in s for s in h["meta"]["skipped_bags"])
    assert main(["prognose", str(tmp_path / "zero"), "--out", str(tmp_path / "pz"), "--no-plots",
                 "--particles", "300"]) == 0
    h = json.loads((tmp_path / "pz" / "rul_history.json").read_text())
    assert h["t"] == [0.0, 1.0, 2.0] and h["meta"]["hours_per_mission"] == 10.0  # renumbered in hours order
    assert any("duplicate mission_index" in s for s in h["meta"]["skipped_bags"])


def test_prognose_notes_another_transmission_type(tmp_path, capsys):
    """The packaged observation model was fitted on N = 101 drives; an N = 50 actuator gets a note."""
    v = FB.replace(FB.VARIANTS["n50"], sim={"gear_ratio": 50, "k_t": 0.35, "duration": 1.5})
    for k in range(3):
        FB.write_variant(tmp_path / "n50", FB.replace(v, name=f"m{k}"), seed=k, mission_index=k,
                         actuator_id="FX-N50")
    assert main(["prognose", str(tmp_path / "n50"), "--out", str(tmp_path / "p"), "--no-plots",
                 "--particles", "300"]) == 0
    h = json.loads((tmp_path / "p" / "rul_history.json").read_text())
    assert any("N = [50.0] differs from the N = [101.0]" in s for s in h["meta"]["notes"])


def test_prognose_on_an_empty_or_missing_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["prognose", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) != 0
    assert "empty: no .mcap bags" in capsys.readouterr().err
    assert main(["prognose", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) != 0
    assert "nowhere: not a directory" in capsys.readouterr().err


def test_feature_study_refuses_bags_without_wear_truth(foreign_actuator, tmp_path, capsys):
    d, _ = foreign_actuator
    rc = main(["prognostic", "features", str(d.parent), "--out", str(tmp_path / "f")])
    err = capsys.readouterr().err
    assert rc != 0 and "no actuator has wear ground truth" in err and "Traceback" not in err


def test_discover_never_adds_effects_that_worsen_held_out_error(foreign_bags, tmp_path, capsys):
    out = tmp_path / "disc"
    assert main(["discover", str(foreign_bags["plain"]), "--out", str(out), "--no-plots"]) == 0
    rep = json.loads((out / "report.json").read_text())
    for s in rep["signals"]:
        if s["identifiable"] and s["error_after"]:
            assert s["error_after"]["rmse"] <= s["error_before"]["rmse"] + 1e-9, s["signal"]
    confirmed = [e for e in rep["effects"] if e.get("confirmed", True)]
    assert (rep["twin_out"] is None) == (not confirmed)


def test_discover_without_torque_sensor_uses_tau_m_only(foreign_bags, tmp_path, capsys):
    out = tmp_path / "disc"
    assert main(["discover", str(foreign_bags["no_torque"]), "--out", str(out), "--no-plots"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert [s["signal"] for s in rep["signals"]] == ["tau_m"]


def test_discover_leaves_out_the_twist_of_encoders_without_common_zero(foreign_bags, tmp_path, capsys):
    out = tmp_path / "disc"
    assert main(["discover", str(foreign_bags["theta_offset"]), "--out", str(out), "--no-plots"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert [s["signal"] for s in rep["signals"]] == ["tau_m"]
    assert any("common zero" in s for s in rep["data_notes"])


def test_discover_repeats_suspect_data(foreign_bags, tmp_path, capsys):
    out = tmp_path / "disc"
    assert main(["discover", str(foreign_bags["speed_rpm"]), "--out", str(out), "--no-plots"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert any("suspect data" in s and "in rpm?" in s for s in rep["data_notes"])


def test_onboard_eval_runs_on_foreign_bags(foreign_bags, tmp_path, capsys):
    # the fixture's 2 s bags are shorter than the 5 s warm-up: nothing can be scored, and it says so
    bags = [str(foreign_bags[n]) for n in ("plain", "rosbags", "no_torque", "no_temp", "dropout")]
    rc = main(["onboard", "eval", *bags, "--quiet"])
    cap = capsys.readouterr()
    assert rc == 1 and "Traceback" not in cap.err
    assert "too short" in cap.out + cap.err
    # long enough foreign bags (other writers, no torque sensor, no temperature) are scored
    long = [str(FB.write_variant(tmp_path / "long", FB.replace(FB.VARIANTS[n], sim={**FB.VARIANTS[n].sim, "duration": 7.0})))
            for n in ("plain", "rosbags", "no_torque", "no_temp")]
    rc = main(["onboard", "eval", *long, "--out", str(tmp_path / "ob"), "--quiet"])
    cap = capsys.readouterr()
    assert rc == 0 and "Traceback" not in cap.err, cap.err
    rep = json.loads((tmp_path / "ob" / "onboard_eval.json").read_text())
    assert rep["n_scored"] == 4, rep
    rc = main(["onboard", "eval", str(foreign_bags["no_kt"]), "--quiet"])
    assert rc != 0 and "torque_constant" in capsys.readouterr().err


def test_a_copied_bag_is_one_mission_not_a_renumbering(tmp_path, capsys):
    """The same recording twice in an actuator folder (a copied bag) is kept once, said so; the mission indices
    stay those of the metadata, so an events file still points at the right missions. Two *different* recordings
    with one mission_index and one start stamp (a tool on simulated time without a counter) are both kept."""
    import shutil

    from hd_prognostic.pipeline import extract_actuator

    plain = FB.replace(FB.VARIANTS["plain"], sim={"duration": 1.0})
    for k in range(4):
        FB.write_variant(tmp_path / "a", FB.replace(plain, name=f"m{k}"), seed=k, mission_index=k,
                         operating_hours=10.0 * k, actuator_id="FX-C")
    shutil.copy(tmp_path / "a" / "m1.mcap", tmp_path / "a" / "copy_of_m1.mcap")
    a = extract_actuator(tmp_path / "a")
    assert list(a.mission_index) == [0, 1, 2, 3] and len(a.paths) == 4
    assert any("second copy of mission 1" in s for s in a.errors)
    for k in range(2):
        FB.write_variant(tmp_path / "z", FB.replace(plain, name=f"z{k}"), seed=k, mission_index=0,
                         operating_hours=0.0, actuator_id="FX-Z")
    z = extract_actuator(tmp_path / "z")
    assert len(z.paths) == 2 and list(z.mission_index) == [0, 1]  # not copies: renumbered, as before
    assert not any("second copy" in s for s in z.errors)


def test_a_flat_fleet_folder_is_grouped_by_actuator_id(tmp_path, capsys):
    """Another tool's fleet: every bag of every actuator in one folder. The units are the metadata's actuator_ids,
    with the same histories as the one-folder-per-actuator layout; a folder mixing both layouts is refused."""
    import shutil

    from hd_prognostic.pipeline import extract_actuator, find_actuator_groups, load_fleet_histories

    plain = FB.replace(FB.VARIANTS["plain"], sim={"duration": 1.0})
    for aid in ("FX-A", "FX-B"):
        for k in range(3):
            FB.write_variant(tmp_path / "tree" / aid, FB.replace(plain, name=f"{aid}_m{k}"), seed=k,
                             mission_index=k, operating_hours=10.0 * k, actuator_id=aid)
    (tmp_path / "flat").mkdir()
    for b in sorted((tmp_path / "tree").rglob("*.mcap")):
        shutil.copy(b, tmp_path / "flat" / b.name)
    g = find_actuator_groups(tmp_path / "flat")
    assert [(n, len(b)) for n, b in g] == [("FX-A", 3), ("FX-B", 3)]
    assert "grouped by their metadata's actuator_id" in capsys.readouterr().err
    flat = [extract_actuator(tmp_path / "flat" / n, bags=b) for n, b in g]
    tree = [extract_actuator(tmp_path / "tree" / n) for n, _ in g]
    assert [a.actuator_id for a in flat] == [a.actuator_id for a in tree] == ["FX-A", "FX-B"]
    for a, b in zip(flat, tree):
        assert list(a.mission_index) == list(b.mission_index) == [0, 1, 2]
        np.testing.assert_array_equal(a.feature("W_load"), b.feature("W_load"))
    with pytest.raises(ValueError, match="never computable"):  # the fleet loader takes the flat folder too
        load_fleet_histories(tmp_path / "flat", exposure="missions")  # (1 s missions: too short for the HI)
    shutil.copy(tmp_path / "flat" / "FX-A_m0.mcap", tmp_path / "tree" / "stray.mcap")
    with pytest.raises(ValueError, match="one layout per fleet folder"):
        find_actuator_groups(tmp_path / "tree")


def test_prognose_picks_one_actuator_of_a_flat_fleet_folder(tmp_path, capsys):
    """`hdphm prognose FLAT_DIR --unit ID` reads that actuator's bags only (the same history as its own folder);
    without --unit the mixed folder is refused with the hint, an unknown unit is named with the ones present."""
    import shutil

    plain = FB.replace(FB.VARIANTS["plain"], sim={"duration": 1.5})
    for aid in ("FX-A", "FX-B"):
        for k in range(3):
            FB.write_variant(tmp_path / "tree" / aid, FB.replace(plain, name=f"{aid}_m{k}"), seed=k + 7 * len(aid),
                             mission_index=k, operating_hours=10.0 * k, actuator_id=aid)
    (tmp_path / "flat").mkdir()
    for b in sorted((tmp_path / "tree").rglob("*.mcap")):
        shutil.copy(b, tmp_path / "flat" / b.name)
    args = ["--no-plots", "--particles", "300"]
    assert main(["prognose", str(tmp_path / "flat"), "--unit", "FX-B", "--out", str(tmp_path / "pf")] + args) == 0
    assert main(["prognose", str(tmp_path / "tree" / "FX-B"), "--out", str(tmp_path / "pt")] + args) == 0
    a, b = (json.loads((tmp_path / p / "rul_history.json").read_text()) for p in ("pf", "pt"))
    assert a["t"] == b["t"] == [0.0, 1.0, 2.0] and a["rul_quantiles"] == b["rul_quantiles"]
    capsys.readouterr()
    assert main(["prognose", str(tmp_path / "flat"), "--out", str(tmp_path / "px")] + args) != 0
    assert "--unit ID" in capsys.readouterr().err
    assert main(["prognose", str(tmp_path / "flat"), "--unit", "FX-C", "--out", str(tmp_path / "px")] + args) != 0
    assert "no actuator 'FX-C' (it holds FX-A, FX-B)" in capsys.readouterr().err


def test_life_model_prognose_notes_another_transmission_type(tmp_path, capsys):
    """A life model fitted from N = 101 bags records its gear ratios; an N = 50 actuator's prognosis says so."""
    from hd_prognostic.lifemodel import LifeModel
    from tests.prognostic.lifesynth import synth_units

    m = LifeModel.fit(synth_units(8, seed=1, censor_frac=0.2)[0], exposure="missions", feature="HF_MTW_IF",
                      time_unit="mission", n_draws=0)
    m.fit_info["gear_ratio"] = [101.0]  # what `hdphm prognostic fit` writes for a fleet of N = 101 bags
    m.to_json(tmp_path / "m.json")
    v = FB.replace(FB.VARIANTS["n50"], sim={"gear_ratio": 50, "k_t": 0.35, "duration": 3.0})
    for k in range(3):
        FB.write_variant(tmp_path / "n50", FB.replace(v, name=f"m{k}"), seed=k, mission_index=k,
                         actuator_id="FX-N50")
    assert main(["prognose", str(tmp_path / "n50"), "--model", str(tmp_path / "m.json"), "--out",
                 str(tmp_path / "p"), "--no-plots"]) == 0
    h = json.loads((tmp_path / "p" / "rul_history.json").read_text())
    assert any("gear ratio 50, the life model was fitted on 101" in s for s in h["meta"]["notes"])
    assert "another transmission type" in capsys.readouterr().err


def test_life_model_fit_notes_a_fleet_mixing_gear_ratios(tmp_path):
    """`hdphm prognostic fit` on bags of two transmission types: the fleet's gear ratios are returned for the model's
    fit_info and a note says one life model is fitted to both."""
    from hd_prognostic.cli import _life_sources

    for aid, var, sim in (("FX-A", "plain", {}), ("FX-B", "n50", {"gear_ratio": 50, "k_t": 0.35})):
        v = FB.replace(FB.VARIANTS[var], sim={**sim, "duration": 3.0})
        for k in range(3):
            FB.write_variant(tmp_path / "fleet" / aid, FB.replace(v, name=f"m{k}"), seed=k, mission_index=k,
                             actuator_id=aid)
    cands, feature, tu, notes, Ns = _life_sources(str(tmp_path / "fleet"), None, "HF_MTW_IF", "missions")
    assert Ns == [50.0, 101.0] and [u.unit for u in cands["missions"]] == ["FX-A", "FX-B"]
    assert any("mixes gear ratios 50, 101" in s for s in notes)
