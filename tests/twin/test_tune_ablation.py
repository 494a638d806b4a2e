"""Optuna search (resumable SQLite study) and the out-of-range ablation, on tiny synthetic data."""

import json

import numpy as np
import pytest

from tests.twin.synth import synth_fleet, synth_mission


def test_tune_is_resumable_sqlite(tmp_path, monkeypatch):
    pytest.importorskip("optuna")
    import hd_twin.tune as T

    small = {"layers": (1, 1), "hidden": (4, 8), "dropout": (0.0, 0.1), "lr": (1e-3, 1e-2), "lambda_init": (1e-2, 1e-1)}
    ms = synth_fleet(4, 1, duration=1.5)
    kw = dict(n_trials=2, storage=None, study_name="t", out_dir=tmp_path, epochs=1, base_preset="tiny", missions=ms,
              space=small)
    best = T.run_study(None, **kw)
    assert (tmp_path / "study.db").is_file() and best["n_trials"] == 2
    best2 = T.run_study(None, **kw)  # same storage + name: continues the study
    assert best2["n_trials"] == 4
    assert set(best2["best_params"]) == set(small)
    assert json.loads((tmp_path / "best.json").read_text())["n_trials"] == 4


def test_ablation_condition_split_and_report(tmp_path):
    from hd_twin.ablation import ood_split, run_ablation

    ms = [synth_mission(f"A{a}", i, K_aero=150 + 100 * a, duration=1.5, seed=a * 3 + i) for a in range(4) for i in range(2)]
    ind, ood, thr = ood_split(ms, "load", 0.75)
    loads = [float(np.percentile(np.abs(m.Q_red), 95)) for m in ms]
    assert all(loads[i] > thr for i in ood) and all(loads[i] <= thr for i in ind) and len(ood) == 2
    with pytest.raises(ValueError, match="unknown ablation condition"):
        ood_split(ms, "colour")
    rep = run_ablation(None, tmp_path, "load", preset="tiny", epochs=1, missions=ms, progress=False)
    assert set(rep["summary"]) == {"pinn", "data_only"}
    assert rep["winner_out_of_range"] in ("pinn", "data_only")
    assert (tmp_path / "ablation_load.png").is_file()
    runs = {r["variant"]: r for r in rep["runs"]}
    assert runs["data_only"]["lambda_c_final"] == 0.0 and runs["pinn"]["lambda_c_final"] > 0
