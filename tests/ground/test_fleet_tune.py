"""``hdphm tune --storage URL``: two worker processes on one Optuna study (SQLite), tiny trial budget."""

from __future__ import annotations

import multiprocessing as mp

import pytest

SMALL = {"layers": (1, 1), "hidden": (4, 8), "dropout": (0.0, 0.1), "lr": (1e-3, 1e-2), "lambda_init": (1e-2, 1e-1)}


def _worker(args):
    storage, out, worker = args
    import hd_twin.tune as T
    from tests.twin.synth import synth_fleet

    ms = synth_fleet(4, 1, duration=1.5)
    return T.run_study(None, n_trials=1, storage=storage, study_name="shared", out_dir=out, epochs=1,
                       base_preset="tiny", missions=ms, space=SMALL, threads=1, worker=worker)


def test_two_processes_share_one_sqlite_study(tmp_path):
    optuna = pytest.importorskip("optuna")
    url = f"sqlite:///{tmp_path / 'study.db'}"
    with mp.get_context("spawn").Pool(2) as pool:
        res = pool.map(_worker, [(url, str(tmp_path / "w0"), 0), (url, str(tmp_path / "w1"), 1)])
    assert sorted(r["worker"] for r in res) == [0, 1]
    study = optuna.load_study(study_name="shared", storage=url)
    done = [t for t in study.trials if t.state.is_finished()]
    assert len(done) == 2  # both processes' trials in the one study, none lost
    assert len({t.number for t in done}) == 2
    assert len({tuple(sorted(t.params.items())) for t in done}) == 2  # own sampler seeds: no repeated trial
