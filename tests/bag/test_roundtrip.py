"""Writer -> reader round trip, file format details, third-party readers."""

from __future__ import annotations

import numpy as np
import yaml
from tests.bag.conftest import T0_NS, make_mission

from hd_bag import iter_messages, read_mission, validate_bag, write_mission
from hd_bag.mission import JOINT_SIGNALS


def test_roundtrip_exact(tmp_path, mission):
    sim = {"internal": {"x_FS": np.arange(mission.n) * 1e-6, "F_b": np.ones(mission.n)},
           "health": {"h": 1e-6, "h_fail": 1e-4}, "effects": {"effects": {"wear": {"on": True, "k": 2.0}}}}
    p = write_mission(tmp_path / "m.mcap", mission, sim=sim)
    m = read_mission(p)
    for k in JOINT_SIGNALS:
        np.testing.assert_array_equal(getattr(m, k), getattr(mission, k))
    np.testing.assert_allclose(m.t, mission.t, atol=1e-9)
    np.testing.assert_allclose(m.t_cmd, mission.t_cmd, atol=1e-9)
    np.testing.assert_array_equal(m.theta_ref, mission.theta_ref)
    for fr in ("gearbox", "motor_winding"):
        np.testing.assert_array_equal(m.temperatures[fr][1], mission.temperatures[fr][1])
    assert m.meta == mission.meta
    assert m.t0_ns == T0_NS
    assert m.sim == {}  # ground truth only on request
    assert m.report.gaps == [] and m.report.n_duplicates == 0 and m.report.n_reordered == 0
    assert (m.segment == 0).all()
    ms = read_mission(p, include_sim=True)
    np.testing.assert_array_equal(ms.sim["/sim/internal"]["x_FS"], sim["internal"]["x_FS"])
    assert ms.sim["/sim/health"]["h_fail"] == 1e-4
    assert ms.sim["/sim/effects"] == sim["effects"]
    assert validate_bag(p) == []


def test_rates_100hz_and_20khz_with_jitter(tmp_path):
    for rate in (100.0, 20_000.0):
        m = make_mission(n=3000, rate=rate)
        rng = np.random.default_rng(1)
        m.t = m.t + rng.uniform(-0.2, 0.2, m.n) / rate  # +-20 % jitter, order kept
        p = write_mission(tmp_path / f"r{int(rate)}.mcap", m)
        r = read_mission(p)
        assert abs(r.fs - rate) / rate < 0.05
        assert r.report.gaps == []
        assert [v for v in validate_bag(p) if v.severity == "error"] == []


def test_schema_channels_and_metadata_as_ros2_bag_writes(tmp_path, mission):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    p = write_mission(tmp_path / "m.mcap", mission, sim={"effects": {"effects": {}}})
    ts = get_typestore(Stores.ROS2_JAZZY)
    with open(p, "rb") as f:
        r = make_reader(f)
        s = r.get_summary()
        assert r.get_header().profile == "ros2"
        for sch in s.schemas.values():
            assert sch.encoding == "ros2msg"
            assert sch.data.decode() == ts.generate_msgdef(sch.name, ros_version=2)[0]
        by_topic = {c.topic: c for c in s.channels.values()}
        for topic, c in by_topic.items():
            assert c.message_encoding == "cdr"
            qos = yaml.safe_load(c.metadata["offered_qos_profiles"])
            want = "transient_local" if topic == "/sim/effects" else "volatile"
            assert qos[0]["durability"] == want and qos[0]["reliability"] == "reliable"
        md = {m.name: m.metadata for m in r.iter_metadata()}
        assert md["hd_mission"]["gear_ratio"] == "100.0" and md["hd_mission"]["seed"] == "7"
        assert s.statistics.channel_message_counts[by_topic["/hd/joint_states"].id] == mission.n


def test_third_party_readers_decode_our_bags(tmp_path, mission):
    from pathlib import Path

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    p = write_mission(tmp_path / "m.mcap", mission)
    with open(p, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        pos = [tuple(m.position) for _, c, _, m in r.iter_decoded_messages(topics=["/hd/joint_states"],
                                                                             log_time_order=True)]
    np.testing.assert_array_equal(np.array(pos), np.stack([mission.theta_m, mission.theta_f], 1))
    with AnyReader([Path(p)]) as ar:
        conns = [c for c in ar.connections if c.topic == "/hd/temperature"]
        frames = [ar.deserialize(raw, c.msgtype).header.frame_id for c, _, raw in ar.messages(connections=conns)]
    assert set(frames) == {"gearbox", "motor_winding"} and len(frames) == 40


def test_cdr_matches_rclpy_serialisation(mission):
    """Our vectorised encoder produces what rclpy deserialises to the same message."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from hd_bag import cdr

    rows = cdr.encode_jointstate(cdr.jointstate_layout(("motor", "output")), np.array([T0_NS + 123]),
                                 np.array([[1.5, -2.5]]), np.array([[3.0, 4.0]]), np.array([[np.nan, 6.0]]))
    msg = deserialize_message(rows[0].tobytes(), JointState)
    assert list(msg.name) == ["motor", "output"] and list(msg.position) == [1.5, -2.5]
    assert msg.header.stamp.sec == T0_NS // 10**9 and msg.header.stamp.nanosec == 123
    back = np.frombuffer(serialize_message(msg), np.uint8)[None, :]
    lay = cdr.parse_jointstate_layout(back[0].tobytes())
    assert cdr.match_layout(back, lay)[0]
    np.testing.assert_array_equal(cdr.decode_doubles(back, lay.offsets[1], 2), [[3.0, 4.0]])


def test_iter_messages_log_time_order_real_ros_classes(tmp_path, mission):
    from sensor_msgs.msg import JointState, Temperature

    p = write_mission(tmp_path / "m.mcap", mission)
    got = list(iter_messages(p))
    lts = [g[2] for g in got]
    assert lts == sorted(lts)
    assert len(got) == mission.n + len(mission.t_cmd) + 40
    js = [g for g in got if g[0] == "/hd/joint_states"]
    assert isinstance(js[0][3], JointState)
    assert js[5][1] == T0_NS + round(mission.t[5] * 1e9)
    assert js[5][3].position[1] == mission.theta_f[5]
    temps = list(iter_messages(p, topics=["/hd/temperature"]))
    assert len(temps) == 40 and isinstance(temps[0][3], Temperature)


def test_streaming_add_serialized_as_a_recorder_would(tmp_path, mission):
    """hdphm record path: messages serialised by rclpy arrive one by one (with rclpy's padding bytes)."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from hd_bag import MissionWriter

    with MissionWriter(tmp_path / "rec.mcap", mission.meta, chunk_seconds=0.1) as w:
        for i in range(300):
            st = T0_NS + i * 1_000_000
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(st, 10**9)
            msg.name = ["motor", "output"]
            msg.position = [float(mission.theta_m[i]), float(mission.theta_f[i])]
            msg.velocity = [1.0, 2.0]
            msg.effort = [3.0, float("nan")]
            w.add_serialized("/hd/joint_states", serialize_message(msg), st)
    r = read_mission(tmp_path / "rec.mcap")
    np.testing.assert_array_equal(r.theta_m, mission.theta_m[:300])
    assert np.isnan(r.Q_red).all() and (r.tau_m == 3.0).all()
