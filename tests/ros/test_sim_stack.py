"""Integration on the real plant simulator: ONNX twin, fitted observation model, ground node, per-mission recording.

One small simulated fleet (module fixture) serves every test: three training
actuators (the tiny twin is trained and the prognostic observation model is
fitted on them, as `hdphm train` / `hdphm prognostic fit-obs` would) and a
fourth actuator whose short life is replayed through the stack.
"""
import json
import os
import sys
import time

import numpy as np
import pytest

pytest.importorskip("rclpy")
from tests.onboard.simfix import faulted_mission, sim_mission

from hd_bag import read_mission, validate_bag, write_mission  # noqa: E402
import hd_ros as ru  # noqa: E402
from hdphm.stack import Stack, run_stack_on_bags  # noqa: E402

pytestmark = pytest.mark.ros

#: stated detection delay of a sudden grease loss (lubrication_loss severity 3, injected mid-mission by
#: hd_sim's fault hook) through the stack, the same bound as the core tests
#: (tests/onboard/test_sim_and_short_path.py, measured there)
FAULT_DELAY_S = 2.0


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    import torch

    from hd_prognostic.pipeline import extract_actuator, fit_population
    from hd_sim import simulate_fleet
    from hd_twin.train import TrainConfig, train_twin

    torch.set_num_threads(1)
    d = tmp_path_factory.mktemp("simfleet")
    simulate_fleet(4, 4, d / "fleet", seed=5, duration=8.0, profiles=("inspection",), progress=False,
                   sim_internal_every=1)
    acts = sorted(p for p in (d / "fleet").iterdir() if p.is_dir())
    train, life = acts[:3], acts[3]
    obs = fit_population([extract_actuator(a, include_truth=True) for a in train])
    obs_path = obs.to_json(d / "obs.json")
    missions = [read_mission(b) for a in train for b in sorted(a.glob("*.mcap"))[:2]]
    model = d / "twin"
    train_twin(missions, model, TrainConfig.from_preset("tiny", epochs=2), progress=False)
    return {"train": [str(a) for a in train], "life": sorted(str(b) for b in life.glob("*.mcap")),
            "obs": str(obs_path), "model": str(model), "dir": d}


def test_life_through_stack_onnx_twin_obs_model_split_recording(fleet, tmp_path, domain_id):
    """A 4-mission life: ONNX twin onboard, finite RUL P5/P50/P95 per mission, one recorded contract
    bag per mission that validates and holds that mission's samples.

    No false-alarm claim here: a 2-epoch tiny twin with lines self-calibrated on a 5 s warm-up does
    raise flags on healthy missions (false alarms are measured by `hdphm onboard eval`)."""
    out = tmp_path / "rec"
    s = run_stack_on_bags(fleet["life"], fleet["model"], str(out), rate="max", domain_id=domain_id, progress=False,
                          obs_model=fleet["obs"], split_per_mission=True,
                          overrides={"prognostic": {"n_particles": 300, "rul_particles": 200}})
    assert s["twin"] == "onnx_twin" and s["errors"] == []
    assert all(f["level"] in (1, 2) and f["actuator"] == "EMA-0003" for f in s["flags"])
    assert s["received_onboard"] == s["published"]
    (act, hist), = s["health_history"].items()
    assert len(hist) == len(fleet["life"])  # one committed filter step per mission
    assert [h["mission_index"] for h in hist] == list(range(len(fleet["life"])))
    for h in hist:
        # P95 may be +inf: more than the node's max_missions horizon (2000) without failing, which a
        # prior fitted on 4 short missions per unit (little wear) can give; P5/P50 must be finite
        assert np.isfinite([h["rul_p5"], h["rul_p50"], h["h_mean"], h["h_p5"], h["h_p95"], h["risk"]]).all(), h
        assert not np.isnan(h["rul_p95"]) and 0 <= h["rul_p5"] <= h["rul_p50"] <= h["rul_p95"], h
    files = s["recorded_files"]
    assert [os.path.basename(f) for f in files] == [f"{act}_m{k:04d}.mcap" for k in range(len(fleet["life"]))]
    for f, src in zip(files, fleet["life"]):
        assert not [v for v in validate_bag(f) if v.severity == "error"], f
        a, b = read_mission(f), read_mission(src)
        assert a.n == b.n and a.meta.mission_index == b.meta.mission_index
        np.testing.assert_array_equal(a.tau_m, b.tau_m)
    assert sum(s["recorded"].values()) >= sum(s["published"].values())
    # the shipped Foxglove layout names only topics and fields (and table columns) these recordings hold
    from hdphm.foxglove import check_layout, layout_paths, load_layout

    assert len(layout_paths(load_layout())) >= 15
    assert check_layout(files[-1]) == []


def test_healthy_then_faulted_sim_bags_flags_only_after_onset(fleet, tmp_path, domain_id):
    h = str(tmp_path / "healthy.mcap")
    f = str(tmp_path / "fault.mcap")
    write_mission(h, sim_mission(1, 3, duration=14.0, t0_ns=1_700_000_000_000_000_000))
    t0 = 1_700_000_100_000_000_000
    write_mission(f, faulted_mission(10.0, seed=3, actuator=1, duration=14.0, t0_ns=t0))
    s = run_stack_on_bags([h, f], None, None, domain_id=domain_id, progress=False)
    assert s["twin"] == "physics_standin"
    assert s["flags"], "the grease loss was not flagged"
    first = min(x["stamp_s"] for x in s["flags"])
    assert 0.0 <= first - (t0 * 1e-9 + 10.0) < FAULT_DELAY_S, first - (t0 * 1e-9 + 10.0)


def test_ground_node_recalibrates_and_pushes_thresholds(fleet, tmp_path, domain_id):
    """The ground node analyses a directory of recorded missions; the twin core applies its update and
    the onboard node monitors the next mission with the ground's lines."""
    from std_msgs.msg import String

    arch = tmp_path / "archive"
    arch.mkdir()
    for a in fleet["train"][:2]:
        for b in sorted(os.listdir(a))[:3]:
            os.symlink(os.path.join(a, b), arch / b)
    st = Stack(domain_id, nodes=("twin", "onboard", "ground"),
               overrides={"ground": {"archive_dir": str(arch), "healthy_missions": 2}})
    reports = []
    st.aux.create_subscription(String, ru.TOPIC_GROUND_REPORT, lambda m: reports.append(json.loads(m.data)), ru.qos("latched"))
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end and not (reports and st.nodes["onboard"].thresholds_all):
            st.spin_for(0.1)
        gr, tw, onb = st.nodes["ground"], st.nodes["twin"], st.nodes["onboard"]
        assert gr.error is None and gr.n_runs == 1
        rep = reports[-1]
        acts = set(rep["actuators"])
        assert len(acts) == 2 and all(len(rep["actuators"][a]["reference"]) == 2 for a in acts)
        assert tw.state["revision"] >= 1 and tw.state["updated_by"] == "ground"
        assert set(tw.state["thresholds"]) == acts and set(onb.thresholds_all) == acts
        for a in acts:
            for c, th in onb.thresholds_all[a].items():
                assert th.source.startswith("ground") and 0 < th.h_warn <= th.h_error and th.sigma > 0
        # recalibration on the 4 reference missions (sim Q_red measured): least squares fit pushed
        rc = rep["recalibration"]
        assert "skipped" not in rc, rc
        assert rc["rows"] >= 2000 and rc["rms_after"] <= rc["rms_before"]
        assert tw.state["params"]["source"].startswith("recalibrated") and onb.twin_params.source.startswith("recalibrated")
        # the next mission of an archived actuator is monitored with the ground's lines
        from hd_ros.replay import Replayer

        a0 = sorted(acts)[0]
        nxt = [b for t in fleet["train"] for b in sorted(os.listdir(t)) if b.startswith(a0)][3]
        src = os.path.join([t for t in fleet["train"] if t.endswith(a0)][0], nxt)
        rep_ = Replayer(st.aux, "max", pump=st.pump)
        rep_.play(src)
        st.pump(force=True)
        assert onb.hardware_id == a0
        assert {c: d.threshold.source for c, d in onb.core.detectors.items()} == {
            c: onb.thresholds_all[a0][c].source for c in onb.core.detectors}
        assert onb.core.calibrated and not onb.errors
        # ... and with the ground's stiffness / friction references (fitted on all the reference samples)
        assert set(tw.state["references"]) == acts and set(onb.references_all) == acts
        for a in acts:
            assert rep["actuators"][a]["references"]["stiffness"]["n"] >= 2000
        refs = rep["actuators"][a0]["references"]
        if "stiffness" in refs:
            assert onb.core.stiffness_status()["reference"] == "ground"
        if "friction" in refs:
            assert onb.core.friction_status()["reference"] == "ground"
        # analysis on request: the std_srvs/Trigger service answers at once and a second report follows
        from std_srvs.srv import Trigger

        from hd_ground.node import SERVICE_ANALYSE

        cli = st.aux.create_client(Trigger, SERVICE_ANALYSE)
        assert cli.wait_for_service(timeout_sec=10.0)
        fut = cli.call_async(Trigger.Request())
        end = time.monotonic() + 10
        while time.monotonic() < end and not fut.done():
            st.spin_for(0.05)
        assert fut.done() and fut.result().success, fut.result()
        n0 = len(reports)
        end = time.monotonic() + 120
        while time.monotonic() < end and len(reports) == n0:
            st.spin_for(0.1)
        assert len(reports) == n0 + 1 and gr.n_runs == 2 and gr.error is None
    finally:
        st.close()


def test_record_split_per_mission_across_processes(tmp_path, domain_id):
    """`hdphm record --split-per-mission` in its own process, two missions replayed from this one at max
    rate (same stamps in both bags): each file holds exactly its mission and validates; SIGTERM ends it."""
    import signal
    import subprocess

    from rclpy.node import Node

    from hd_ros.replay import Replayer

    bags = []
    for k in range(2):
        m = sim_mission(0, k, duration=3.0, mission_index=k)
        bags.append(str(tmp_path / f"b{k}.mcap"))
        write_mission(bags[-1], m)
    out = tmp_path / "rec"
    proc = subprocess.Popen([sys.executable, "-m", "hdphm.cli", "record", "--split-per-mission", "--out", str(out),
                             "--domain-id", str(domain_id)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ctx = ru.init_context(domain_id)
    node = Node("test_replay", context=ctx)
    try:
        rep = Replayer(node, "max")
        end = time.monotonic() + 30  # the recorder subscribes to each topic once it discovers its publisher
        while time.monotonic() < end and any(p.get_subscription_count() == 0 for p in rep.pubs.values()):
            time.sleep(0.05)
        for b in bags:
            rep.play(b)
        for p in rep.pubs.values():
            p.wait_for_all_acked()
        time.sleep(3.0)  # acked = in the recorder's DDS history; give its callbacks time to file them
    finally:
        node.destroy_node()
        import rclpy

        rclpy.try_shutdown(context=ctx)
        proc.send_signal(signal.SIGTERM)
        log = proc.communicate(timeout=30)[0]
    assert proc.returncode == 0, log
    files = sorted(out.glob("*.mcap"))
    assert [f.name for f in files] == ["EMA-0000_m0000.mcap", "EMA-0000_m0001.mcap"], log
    for f, b in zip(files, bags):
        assert not [v for v in validate_bag(str(f)) if v.severity in ("error", "warning")], f
        a, src = read_mission(str(f)), read_mission(b)
        assert a.n == src.n and len(a.t_cmd) == len(src.t_cmd)
        np.testing.assert_array_equal(a.tau_m, src.tau_m)


def test_onboard_rt_thread_mode(tmp_path, domain_id):
    """rt_thread: joint states on their own executor thread; every sample processed, fault flagged."""
    from tests.onboard.synth import make_mission

    from hd_ros.replay import Replayer

    bag = str(tmp_path / "f.mcap")
    write_mission(bag, make_mission(duration=8.0, seed=31, fault_at=6.0))
    st = Stack(domain_id, nodes=("twin", "onboard"), overrides={"onboard": {"rt_thread": True}})
    try:
        st.spin_for(0.3)
        rep = Replayer(st.aux, "max", pump=st.pump)
        rep.play(bag)
        onb = st.nodes["onboard"]
        end = time.monotonic() + 20
        while time.monotonic() < end and onb.n_msgs[ru.TOPIC_JOINT_STATES] < rep.counts[ru.TOPIC_JOINT_STATES]:
            st.spin_for(0.05)
        assert onb.n_msgs[ru.TOPIC_JOINT_STATES] == rep.counts[ru.TOPIC_JOINT_STATES] == 8000
        assert onb.core.health.n_samples == 8000 and not onb.errors
        assert onb.flags and 0 <= onb.flags[0][1] * 1e-9 - (1_700_000_000 + 6.0) < 0.5
    finally:
        st.close()


def test_onnx_twin_short_path_equals_block_path(fleet):
    """The ONNX twin's per-sample step gives the one-row-block numbers (LSTM state carried)."""
    from hd_onboard.core import OnboardCore
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    m = sim_mission(3, 5, duration=6.0)
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    V[3000:3003, 4] = np.nan
    p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
    a = OnboardCore(make_expected(fleet["model"], p), p)
    A = np.concatenate([a.push(stamps[i:i + 1], V[i:i + 1]).table for i in range(len(stamps))])
    b = OnboardCore(make_expected(fleet["model"], p), p)
    assert a.expected.kind == b.expected.kind == "onnx_twin"
    for s_, v_ in zip(stamps.tolist(), V.tolist()):
        b.push_one(s_, v_)
    np.testing.assert_allclose(b.take_rows(), A, rtol=1e-9, atol=1e-9, equal_nan=True)
