"""The twin as identified physics path + gated learned remainder (issue 11).

* the gate rule: never worse than the physics path on any held-out group of the training data;
* end to end on synthetic missions: the physics path is identified and stored, the twin's held-out
  NRMSE is not above its physics path's, ONNX streaming equals batch (remainder exactly, the
  physics path exactly when the whole segment is one call);
* the same never-worse check on today's plant (a small fleet of hd_sim bags, one unit held out).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from hd_twin import data as D
from hd_twin.physpath import choose_gate
from tests.twin.synth import synth_fleet, synth_mission

identify = pytest.importorskip("hd_twin.identify", reason="needs the shared identification (hd_twin.identify)")


def test_gate_rule_never_worse_on_any_group():
    rng = np.random.default_rng(0)
    n = 500
    e = rng.normal(0, 1, n)
    helpful = e + rng.normal(0, 0.3, n)  # explains most of what the physics path leaves
    y = [np.full(n, 10.0) + e, np.full(n, 10.0) + e]
    q = [np.full(n, 10.0), np.full(n, 10.0)]
    g, det = choose_gate(y, q, [helpful, helpful])
    assert 0.8 < g <= 1.0 and len(det["groups"]) == 2
    # a remainder that hurts one group is switched off
    g2, _ = choose_gate(y, q, [helpful, -helpful])
    assert g2 == 0.0
    # an over-confident remainder is shrunk to the smallest per-group optimum
    g3, det3 = choose_gate(y, q, [2 * helpful, 4 * helpful])
    assert g3 == pytest.approx(min(d["g_opt"] for d in det3["groups"]))
    for yt, qp, r in zip(y, q, [2 * helpful, 4 * helpful]):
        assert np.mean((yt - qp - g3 * r) ** 2) <= np.mean((yt - qp) ** 2)
    assert choose_gate([], [], [])[0] == 0.0


@pytest.fixture(scope="module")
def synth_model(tmp_path_factory):
    from hd_twin.train import TrainConfig, train_twin

    out = tmp_path_factory.mktemp("twin_resid")
    res = train_twin(synth_fleet(4, 2, duration=3.0), out,
                     TrainConfig.from_preset("tiny", epochs=3, plots=False, physics_path="identified"), progress=False)
    return out, res


def _held_out_metrics(model_dir, missions):
    from hd_twin.train import eval_model

    return eval_model(model_dir, missions)


def test_physics_path_is_identified_and_stored(synth_model):
    out, res = synth_model
    cfg = json.loads((out / "config.json").read_text())
    pp = cfg["physics_path"]
    assert pp["kind"] == "identified" and 0.0 <= pp["gate"] <= 1.0
    assert set(pp["identified"]["names"]) >= {"tau_m", "alpha_m", "coulomb", "omega_m"}
    summ = res.metrics["physics_path"]
    a = summ["terms"]["tau_m"]
    # synth missions: Q = N (tau - friction - J_in alpha) - J_CS alpha_f: the load-path coefficient is N
    N = res.pinn.params.N
    assert abs(a["coef"] - N) < 0.05 * N and a["sd"] > 0
    v = res.metrics["validation"]
    assert v["nrmse_pct"] <= v["physics_only"]["nrmse_pct"] + 1e-9  # by construction on the validation units


def test_held_out_never_worse_than_the_physics_path(synth_model):
    out, _ = synth_model
    held = [synth_mission("EMA-H1", 0, seed=501, K_aero=260.0, duration=3.0),
            synth_mission("EMA-H2", 0, seed=502, K_aero=330.0, duration=3.0)]
    met = _held_out_metrics(out, held)
    assert met["physics_only"]["nrmse_pct"] < 5.0
    assert met["nrmse_pct"] <= met["physics_only"]["nrmse_pct"] * 1.0 + 1e-9


def test_streaming_equals_batch_with_a_physics_path(synth_model):
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import load_pinn, predict_outputs, q_from_outputs

    out, _ = synth_model
    m = synth_mission("EMA-S", 0, seed=77, duration=2.0)
    pinn, norm, cfg = load_pinn(out)
    segs = D.preprocess(m, cfg["preprocessing"]["fs_model"], names=cfg["features"])
    outs = predict_outputs(pinn, segs, norm)
    ref = q_from_outputs(pinn, segs, outs)[0]
    ref_rem = float(pinn.gate) * (pinn.r_mean + pinn.r_std * outs[0][:, 0])
    X = D.mission_inputs(m)
    tw = StreamingTwin(out, fs_in=m.fs)
    whole = tw.step(X)
    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(whole["Q_red"], ref, rtol=0, atol=1e-5 * scale)  # one call: exactly batch
    tw.reset(m.fs)
    parts = [tw.step(X[i:i + 1]) for i in range(40)] + [tw.step(X[i:i + 25]) for i in range(40, len(X), 25)]
    q = np.concatenate([p["Q_red"] for p in parts])
    qp = np.concatenate([p["Q_phys"] for p in parts])
    # the ONNX remainder equals PyTorch's sample by sample and in blocks
    np.testing.assert_allclose(q - qp, ref_rem, rtol=0, atol=1e-5 * scale)
    # the physics path streamed (newest samples from the end-of-window fit) stays close to batch
    d = qp - segs[0].Q_phys
    assert np.sqrt(np.mean(d[20:] ** 2)) < 0.05 * np.std(segs[0].Q_phys)


def test_never_worse_on_todays_plant(small_fleet_dir):
    from hd_twin.train import TrainConfig, evaluate, load_missions, train_twin

    ms = load_missions([small_fleet_dir], progress=False)
    acts = sorted({m.meta.actuator_id for m in ms})
    train = [m for m in ms if m.meta.actuator_id != acts[-1]]
    test = [m for m in ms if m.meta.actuator_id == acts[-1]]
    res = train_twin(train, None, TrainConfig.from_preset("tiny", epochs=2, plots=False, export_onnx=False,
                                                          physics_path="identified"), progress=False)
    fs = res.config["preprocessing"]["fs_model"]
    segs = [s for m in test for s in D.preprocess(m, fs, names=res.config["features"])]
    met = evaluate(res.pinn, segs, res.norm, residuals=False)
    assert np.isfinite(met["physics_only"]["nrmse_pct"]) and met["physics_only"]["nrmse_pct"] < 10.0
    assert met["nrmse_pct"] <= met["physics_only"]["nrmse_pct"] + 1e-9
