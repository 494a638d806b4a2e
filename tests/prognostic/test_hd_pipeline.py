"""Features on a tiny simulated wear sweep; the bag -> features -> PF -> RUL pipeline and its CLI."""

import json

import numpy as np
import pytest

hd_sim = pytest.importorskip("hd_sim.plant")


def _sweep_missions(levels_um, seed=0, duration=10.0, q_nan=False):
    from hd_sim.params import nominal
    from hd_sim.plant import simulate_mission

    out = []
    for i, h in enumerate(levels_um):
        m, truth = simulate_mission(nominal(), None, "inspection", seed, duration=duration,
                                    health={"h_plus": h * 1e-6, "h_minus": h * 1e-6}, mission_index=i)
        if q_nan:
            m.Q_red[:] = np.nan
        out.append(m)
    return out


@pytest.mark.parametrize("q_nan", [False, True])
def test_features_monotone_on_simulated_wear_sweep(q_nan):
    from hd_onboard.features import mission_features

    levels = [0.0, 12.0, 24.0, 36.0]
    f = [mission_features(m) for m in _sweep_missions(levels, q_nan=q_nan)]
    for name in ("HF_MTW_IF", "lost_motion"):
        v = np.array([x[name] for x in f])
        assert np.all(np.diff(v) > 0), (name, v)
    # the in-flight feature separates new from end-of-life wear by a wide margin
    assert f[-1]["HF_MTW_IF"] > 1.5 * f[0]["HF_MTW_IF"]
    assert f[0]["torque_source"] == ("N*eta*tau_m" if q_nan else "Q_red")


def test_prognose_cli_and_metrics(tmp_path):
    from hd_sim.fleet import simulate_fleet

    from hd_prognostic.pipeline import extract_actuator, fit_population
    from hdphm.cli import main

    fleet = tmp_path / "fleet"
    simulate_fleet(2, 4, fleet, seed=3, duration=6.0, progress=False)
    train = extract_actuator(fleet / "EMA-0000", include_truth=True)
    assert train.h_true is not None and np.all(np.diff(train.h_true) > 0)
    obs = fit_population([train], degree=1)
    obs_path = obs.to_json(tmp_path / "obs.json")
    # the estimator side never sees truth
    test = extract_actuator(fleet / "EMA-0001")
    assert test.h_true is None
    # a corrupt bag in the folder is skipped with its name, the mission becomes predict-only
    bad = fleet / "EMA-0001" / "EMA-0001_m0002.mcap"
    bad.write_bytes(bad.read_bytes()[:200])
    out = tmp_path / "out"
    rc = main(["prognose", str(fleet / "EMA-0001"), "--out", str(out), "--obs-model", str(obs_path),
               "--particles", "300", "--no-plots"])
    assert rc == 0
    hist = json.loads((out / "rul_history.json").read_text())
    assert hist["t"] == [0.0, 1.0, 2.0, 3.0]
    assert np.isnan(float(hist["z"][2]))  # the skipped mission
    assert any("EMA-0001_m0002.mcap" in e for e in hist["meta"]["skipped_bags"])
    assert (out / "rul_history.csv").exists()
    rc = main(["metrics", str(out / "rul_history.json"), "--truth", "10"])
    assert rc == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["n_predictions"] == 4 and (out / "alpha_lambda.png").exists()
    assert len(hist["rul_quantiles"]) == 4 and np.isfinite(m["crps_mean"])
