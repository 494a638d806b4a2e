"""Real-data fits (NASA battery, Virkler), observation model, health features on synthetic missions."""

import json

import numpy as np
import pytest

from hd_bag.mission import Mission, MissionMeta
from hd_onboard.features import StiffnessLaw, block_features, mission_features, window_features
from hd_prognostic import realdata as R
from hd_prognostic.observation import ObservationModel

from tests.prognostic.lifesynth import MEASURED

needs_data = pytest.mark.skipif(not (MEASURED / "nasa_battery").is_dir() or not (MEASURED / "virkler").is_dir(),
                                reason="measured data folder not found (set HDPHM_MEASURED_DATA)")


@needs_data
def test_battery_loo_runs_and_beats_nothing_silly():
    out = R.run_battery(MEASURED / "nasa_battery", cells=("B0005", "B0006"), eol_fracs=(0.7,), n_particles=300, t_start=60)
    assert set(out["units"]) == {"B0005@0.7", "B0006@0.7"}
    for u in out["units"].values():
        m = u["metrics"]
        assert m["n_predictions"] > 10
        # near EOL the median is within 50 % of the true RUL on average (sanity, not a tuned figure)
        assert 0 < m["cra"] <= 1


def test_battery_bad_file(tmp_path):
    (tmp_path / "B9.csv").write_text("cycle,capacity_ah\n1,2.0\n")
    with pytest.raises(ValueError, match="B9.csv"):
        R.load_battery("B9", tmp_path)


@needs_data
def test_virkler_units_and_paris_fit():
    specs = R.load_virkler(MEASURED / "virkler")
    assert len(specs) == 68
    # failure at 49.8 mm between 200 k and 330 k cycles for every specimen (the known scatter)
    nf = np.array([s.N_fail for s in specs])
    assert nf.min() > 2.0e5 and nf.max() < 3.3e5
    fit = R.fit_paris(specs[::8])
    assert 2.5 < fit["m"] < 5.0
    out = R.run_virkler(MEASURED / "virkler", n_particles=300, max_specimens=2)
    assert len(out["units"]) == 4
    assert out["aggregate"]["cra"] > 0.5


def test_observation_model_fit_and_json(tmp_path):
    rng = np.random.default_rng(0)
    h = rng.uniform(0, 40e-6, 3000)
    y = 2e-5 + 1.5 * h + (1e-6 + 0.1 * h) * rng.standard_normal(3000)
    ob = ObservationModel.fit(h, y, degree=2)
    assert ob.fit_info["mean_monotone_on_range"]
    # heteroscedastic: spread grows with wear
    assert ob.std(40e-6) > 2 * ob.std(0.0)
    assert abs(ob.std(40e-6) - (1e-6 + 0.1 * 40e-6)) < 0.2 * (1e-6 + 0.1 * 40e-6)
    p = ob.to_json(tmp_path / "o.json")
    ob2 = ObservationModel.from_json(p)
    assert np.allclose(ob2.mean(h[:10]), ob.mean(h[:10]))
    p.write_text(json.dumps({"kind": "other"}))
    with pytest.raises(ValueError, match="o.json"):
        ObservationModel.from_json(p)


def _mission(A2, backlash, q_nan=False, nan_frac=0.0, seed=0, N=100.0):
    rng = np.random.default_rng(seed)
    fs, T = 500.0, 16.0
    t = np.arange(0, T, 1 / fs)
    thf = np.deg2rad(15) * np.sin(2 * np.pi * 0.5 * t)
    thm = N * thf
    Q = 600 * np.sin(2 * np.pi * 0.5 * t + 0.3)
    te = A2 * np.sin(2 * thm + 0.4) + 0.5 * backlash * np.sign(Q)
    tf = thm / N + StiffnessLaw().twist(Q) + te + 2e-6 * rng.standard_normal(len(t))
    wm = np.gradient(thm, t)
    tau = Q / (N * 0.8) + 0.01 * np.sign(wm) + 2e-4 * wm
    Qm = np.full_like(Q, np.nan) if q_nan else Q.copy()
    if nan_frac:
        bad = rng.random(len(t)) < nan_frac
        tf[bad] = np.nan
    meta = MissionMeta("EMA-T", 0, 0.0, N, 0.1)
    return Mission(meta, t, thm, tf, wm, np.gradient(thm / N, t), tau, Qm, t, thf,
                   temperatures={"gearbox": (t[::500], np.full(len(t[::500]), 30.0))})


@pytest.mark.parametrize("q_nan", [False, True])
def test_features_monotone_in_synthetic_wear(q_nan):
    levels = [(1e-5, 0.0), (2e-5, 5e-5), (4e-5, 1.5e-4), (8e-5, 3e-4)]
    f = [mission_features(_mission(a, b, q_nan=q_nan, nan_frac=0.05)) for a, b in levels]
    ke = [x["ke_2x"] for x in f]
    lm = [x["lost_motion"] for x in f]
    assert np.all(np.diff(ke) > 0) and np.all(np.diff(lm) > 0)
    assert abs(ke[2] - 4e-5) < 0.1 * 4e-5
    assert f[0]["torque_source"] == ("N*eta*tau_m" if q_nan else "Q_red")
    assert np.isfinite(f[0]["W_load"]) and np.isfinite(f[0]["cs_gain"])


def test_window_features_and_bad_input():
    m = _mission(2e-5, 1e-4)
    w = window_features(m, window_s=4.0)
    assert len(w) == 4 and all(abs(x["ke_2x"] - 2e-5) < 4e-6 for x in w)
    with pytest.raises(ValueError, match="gear_ratio"):
        block_features(m.t, m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red, -3, 0.1)
    with pytest.raises(ValueError, match="equal length"):
        block_features(m.t, m.theta_m[:-1], m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red, 100, 0.1)
    # too little wave-generator motion: NaN orders with a reason, no crash
    sl = slice(0, 30)
    f = block_features(m.t[sl], m.theta_m[sl] * 0 + 1.0, m.theta_f[sl], m.omega_m[sl], m.omega_f[sl], m.tau_m[sl],
                       m.Q_red[sl], 100, 0.1)
    assert np.isnan(f["ke_2x"]) and any("turns" in n for n in f["notes"])


def test_baseline_normalisation_is_causal():
    ob = ObservationModel(baseline="subtract", n_baseline=3)
    assert ob.normalise([5.0, 7.0, np.nan, 9.0, 11.0]).tolist()[:2] == [0.0, 1.0]
    y = ob.normalise([5.0, 7.0, np.nan, 9.0, 11.0])
    assert np.isnan(y[2]) and y[3] == 2.0 and y[4] == 4.0
    # the value at mission k does not change when later missions arrive
    assert np.allclose(ob.normalise([5.0, 7.0])[:2], y[:2])
    ratio = ObservationModel(baseline="ratio", n_baseline=1).normalise([2.0, 4.0])
    assert ratio.tolist() == [1.0, 2.0]


def test_derived_motor_angle_makes_ke_features_unobservable():
    m = _mission(2e-5, 1e-4)
    f = block_features(m.t, m.theta_m, m.theta_m / 100.0, m.omega_m, m.omega_f, m.tau_m, m.Q_red, 100.0, 0.1)
    assert np.isnan(f["HF_MTW_IF"]) and any("derived" in n for n in f["notes"])
    assert np.isfinite(f["cs_gain"])  # the current-speed features do not need the output encoder


@needs_data
def test_battery_export_runs_through_the_life_model(tmp_path):
    """The NASA cells as HI CSV + events (file arguments only), then fit and prognose on the CSV path."""
    from hd_prognostic.lifemodel import read_events, read_hi_csv
    from hdphm.cli import main as hdphm

    assert hdphm(["prognostic", "battery", "--data", str(MEASURED / "nasa_battery"), "--export", str(tmp_path)]) == 0
    units = {u.unit: u for u in read_hi_csv(tmp_path / "battery_hi.csv")}
    ev = read_events(tmp_path / "battery_events.csv")
    assert set(units) == {"B0005", "B0006", "B0007"}
    for c, e in ev.items():  # failure = first cycle at or below 80 % of the rated 2 Ah
        u = units[c]
        k = int(np.flatnonzero(u.y <= 1.6)[0])
        assert e.failure == u.t[k]
    assert hdphm(["prognostic", "fit", str(tmp_path / "battery_hi.csv"), "--events", str(tmp_path / "battery_events.csv"),
                  "--out", str(tmp_path / "m.json")]) == 0
    fi = json.loads((tmp_path / "m.json").read_text())["fit_info"]  # the CLI defaults: both path families by AIC,
    assert set(fi["path_aic"]) == {"power", "paris"}  # and without --failure-level the failures are found-failed events
    assert "failure_at" not in fi and fi["failure_at_rule"].startswith("no failure level")
    assert hdphm(["prognose", str(tmp_path / "battery_hi.csv"), "--unit", "B0006", "--model", str(tmp_path / "m.json"),
                  "--out", str(tmp_path / "p"), "--samples", "200", "--no-plots"]) == 0
    assert json.loads((tmp_path / "p" / "rul_history.json").read_text())["unit"] == "B0006"
