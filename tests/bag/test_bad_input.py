"""Every kind of bad input gives a clear BagError naming the file and the problem (or a violation)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from tests.bag.conftest import T0_NS, make_mission

from hd_bag import BagError, MissionMeta, MissionWriter, read_mission, validate_bag, write_mission
from hd_bag.cdr import SCHEMAS


def _ros2_writer_bag(path, *, meta=None, topics=("js", "cmd", "temp"), js_type="sensor_msgs/msg/JointState",
                     names=("motor", "output"), n=300):
    """A bag written with mcap-ros2-support's own Writer (another tool)."""
    from mcap_ros2.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        js = w.register_msgdef(js_type, SCHEMAS.get(js_type, "float64 data\n"))
        tmp = w.register_msgdef("sensor_msgs/msg/Temperature", SCHEMAS["sensor_msgs/msg/Temperature"])
        jsd = w.register_msgdef("sensor_msgs/msg/JointState", SCHEMAS["sensor_msgs/msg/JointState"])
        for i in range(n):
            st = T0_NS + i * 1_000_000
            hdr = {"stamp": {"sec": st // 10**9, "nanosec": st % 10**9}, "frame_id": ""}
            if "js" in topics:
                if js_type.endswith("JointState"):
                    msg = {"header": hdr, "name": list(names), "position": [0.01 * i * 100, 0.01 * i][:len(names)],
                           "velocity": [1000.0, 10.0][:len(names)], "effort": [0.1, 2.0][:len(names)]}
                else:
                    msg = {"data": 1.0}
                w.write_message("/hd/joint_states", js, msg, log_time=st, publish_time=st)
            if "cmd" in topics and i % 10 == 0:
                w.write_message("/hd/command", jsd, {"header": hdr, "name": ["output"], "position": [0.01 * i],
                                                     "velocity": [], "effort": []}, log_time=st, publish_time=st)
            if "temp" in topics and i % 100 == 0:
                w.write_message("/hd/temperature", tmp, {"header": dict(hdr, frame_id="gearbox"),
                                                         "temperature": 25.0, "variance": 0.0},
                                log_time=st, publish_time=st)
        if meta is not False:
            md = meta if meta is not None else MissionMeta("EMA-9", 0, 0.0, 100.0, 0.1, "test_bench").to_record()
            w._writer.add_metadata("hd_mission", md)
        w.finish()
    return str(path)


def test_bag_from_mcap_ros2_writer_passes(tmp_path):
    p = _ros2_writer_bag(tmp_path / "other.mcap")
    assert [v for v in validate_bag(p) if v.severity == "error"] == []
    m = read_mission(p)
    assert m.n == 300 and m.meta.actuator_id == "EMA-9"
    np.testing.assert_allclose(m.theta_f, 0.01 * np.arange(300))
    assert len(m.theta_ref) == 30 and m.temperatures["gearbox"][1][0] == 25.0


def test_bag_from_rosbags_writer_passes(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    JS = ts.types["sensor_msgs/msg/JointState"]
    TM = ts.types["sensor_msgs/msg/Temperature"]
    Hdr = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    out = tmp_path / "rb"
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cj = w.add_connection("/hd/joint_states", JS.__msgtype__, typestore=ts)
        cc = w.add_connection("/hd/command", JS.__msgtype__, typestore=ts)
        ct = w.add_connection("/hd/temperature", TM.__msgtype__, typestore=ts)
        for i in range(500):
            st = T0_NS + i * 500_000  # 2 kHz
            h = Hdr(stamp=Time(sec=st // 10**9, nanosec=st % 10**9), frame_id="")
            # names in the other order: the reader maps by name
            msg = JS(header=h, name=["output", "motor"], position=np.array([0.001 * i, 0.1 * i]),
                     velocity=np.array([1.0, 100.0]), effort=np.array([5.0, 0.05]))
            w.write(cj, st, ts.serialize_cdr(msg, JS.__msgtype__))
            if i % 5 == 0:
                w.write(cc, st, ts.serialize_cdr(JS(header=h, name=["output"], position=np.array([0.001 * i]),
                                                    velocity=np.array([]), effort=np.array([])), JS.__msgtype__))
            if i % 250 == 0:
                h2 = Hdr(stamp=h.stamp, frame_id="motor_winding")
                w.write(ct, st, ts.serialize_cdr(TM(header=h2, temperature=60.0, variance=0.0), TM.__msgtype__))
    bag = next(iter(out.glob("*.mcap")))
    # rosbags has no API for MCAP metadata records: add ours by appending? No: rewrite via our
    # low-level scan is not a writer. Instead check the missing-metadata error, then add it.
    with pytest.raises(BagError, match="no 'hd_mission' metadata record"):
        read_mission(bag)
    from mcap.reader import make_reader
    from mcap.writer import Writer as MW

    fixed = tmp_path / "rb_meta.mcap"
    with open(bag, "rb") as fi, open(fixed, "wb") as fo:
        r = make_reader(fi)
        w2 = MW(fo)
        w2.start(profile=r.get_header().profile, library="copy")
        sch = {}
        chs = {}
        for s, c, msg in r.iter_messages():
            if s.id not in sch:
                sch[s.id] = w2.register_schema(s.name, s.encoding, s.data)
            if c.id not in chs:
                chs[c.id] = w2.register_channel(c.topic, c.message_encoding, sch[s.id], c.metadata)
            w2.add_message(chs[c.id], msg.log_time, msg.data, msg.publish_time)
        w2.add_metadata("hd_mission", MissionMeta("RB-1", 1, 2.0, 100.0, 0.1, "flight").to_record())
        w2.finish()
    assert [v for v in validate_bag(fixed) if v.severity == "error"] == []
    m = read_mission(fixed)
    assert m.n == 500 and abs(m.fs - 2000) < 1
    np.testing.assert_allclose(m.theta_m, 0.1 * np.arange(500))
    np.testing.assert_allclose(m.theta_f, 0.001 * np.arange(500))
    np.testing.assert_allclose(m.tau_m, 0.05)
    assert "motor_winding" in m.temperatures


def test_not_an_mcap(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_text("t_s,pos\n0,1\n")
    with pytest.raises(BagError, match=r"x\.mcap: not an MCAP file"):
        read_mission(p)
    assert "not an MCAP" in validate_bag(p)[0].problem


def test_empty_missing_and_directory(tmp_path):
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(BagError, match=r"e\.mcap: file is empty"):
        read_mission(tmp_path / "e.mcap")
    with pytest.raises(BagError, match="no such file"):
        read_mission(tmp_path / "nope.mcap")
    with pytest.raises(BagError, match="is a directory"):
        read_mission(tmp_path)


def test_truncated_before_any_data_is_fatal(tmp_path, mission):
    p = write_mission(tmp_path / "m.mcap", mission)
    data = open(p, "rb").read()
    (tmp_path / "t.mcap").write_bytes(data[:300])  # header, schemas, metadata at most
    with pytest.raises(BagError, match=r"t\.mcap: .*joint_states"):
        read_mission(tmp_path / "t.mcap")


def test_truncated_mid_file_recovers(tmp_path):
    m = make_mission(n=5000)
    p = write_mission(tmp_path / "m.mcap", m, chunk_seconds=0.5)
    data = open(p, "rb").read()
    (tmp_path / "t.mcap").write_bytes(data[:len(data) // 2])
    r = read_mission(tmp_path / "t.mcap")
    assert 0 < r.n < m.n
    np.testing.assert_array_equal(r.theta_f, m.theta_f[:r.n])
    assert any("truncated" in s for s in r.report.notes)


def test_corrupt_chunk_bytes(tmp_path, mission):
    p = write_mission(tmp_path / "m.mcap", mission, compression="none")
    data = bytearray(open(p, "rb").read())
    i = data.find(b"motor\x00") + 200  # inside the first chunk's message data
    data[i:i + 8] = b"\xff" * 8
    (tmp_path / "c.mcap").write_bytes(bytes(data))
    with pytest.raises(BagError, match=r"c\.mcap: .*CRC mismatch"):
        read_mission(tmp_path / "c.mcap")
    p = write_mission(tmp_path / "z.mcap", mission, compression="zstd")
    data = bytearray(open(p, "rb").read())
    j = len(data) // 2
    data[j:j + 64] = os.urandom(64)
    (tmp_path / "cz.mcap").write_bytes(bytes(data))
    with pytest.raises(BagError, match=r"cz\.mcap: "):
        read_mission(tmp_path / "cz.mcap")
    assert validate_bag(tmp_path / "cz.mcap")[0].severity == "error"


def test_wrong_message_type_on_contract_topic(tmp_path):
    p = _ros2_writer_bag(tmp_path / "w.mcap", js_type="std_msgs/msg/Float64")
    with pytest.raises(BagError, match=r"w\.mcap: /hd/joint_states: wrong message type 'std_msgs/msg/Float64'"):
        read_mission(p)
    assert any(v.topic == "/hd/joint_states" and "wrong message type" in v.problem for v in validate_bag(p))


def test_missing_joint_states_is_fatal(tmp_path):
    p = _ros2_writer_bag(tmp_path / "nj.mcap", topics=("cmd", "temp"))
    with pytest.raises(BagError, match=r"nj\.mcap: /hd/joint_states: no /hd/joint_states messages"):
        read_mission(p)


def test_joint_names_missing_is_fatal(tmp_path):
    p = _ros2_writer_bag(tmp_path / "nm.mcap", names=("left", "right"))
    with pytest.raises(BagError, match="joint name 'motor' missing"):
        read_mission(p)


@pytest.mark.parametrize("meta, match", [
    (False, "no 'hd_mission' metadata record"),
    ({"contract": "1", "actuator_id": "A"}, r"lacks required keys \['mission_index'"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), gear_ratio="-5"), "gear_ratio = -5.0 is not physical"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), gear_ratio="0"), "gear_ratio = 0.0 is not physical"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), torque_constant="nan"), "torque_constant = nan is not"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), operating_hours="inf"), "operating_hours = inf"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), mission_index="x"), "mission_index = 'x' is not"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), source="lab"), "source = 'lab'"),
    (dict(MissionMeta("A", 0, 0.0, 100.0, 0.1).to_record(), contract="2"), "contract version '2'"),
])
def test_bad_metadata(tmp_path, meta, match):
    p = _ros2_writer_bag(tmp_path / "meta.mcap", meta=meta)
    with pytest.raises(BagError, match=r"meta\.mcap: .*" + match):
        read_mission(p)
    assert any(match.split(" ")[0].strip("\\(") in v.problem for v in validate_bag(p) if v.severity == "error")


def test_writer_refuses_absurd_metadata_and_data(tmp_path):
    with pytest.raises(BagError, match="gear_ratio"):
        MissionWriter(tmp_path / "a.mcap", MissionMeta("A", 0, 0.0, -1.0, 0.1))
    m = make_mission(n=10)
    m.temperatures = {"housing": (m.t, m.t)}
    with pytest.raises(BagError, match="temperature frame 'housing'"):
        write_mission(tmp_path / "b.mcap", m)


def test_unknown_temperature_frame_flagged(tmp_path):
    m = make_mission(n=500)
    with MissionWriter(tmp_path / "f.mcap", m.meta) as w:
        s = T0_NS + np.round(m.t * 1e9).astype(np.int64)
        w.add_joint_states(s, m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red)
        from hd_bag import cdr

        w.add_rows("/hd/temperature", cdr.encode_temperature("housing", s[::100], np.full(5, 30.0)), s[::100])
    r = read_mission(tmp_path / "f.mcap")
    assert r.temperatures == {} and any("housing" in n for n in r.report.notes)
    v = [x for x in validate_bag(tmp_path / "f.mcap") if "housing" in x.problem]
    assert len(v) == 5 and v[0].severity == "error"


def test_rate_outside_contract_is_violation(tmp_path):
    m = make_mission(n=200, rate=20.0)
    p = write_mission(tmp_path / "slow.mcap", m)
    assert read_mission(p).n == 200
    assert any("outside the contract" in v.problem for v in validate_bag(p) if v.severity == "error")
