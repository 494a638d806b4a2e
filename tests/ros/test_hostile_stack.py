"""Issue 13 on the running stack: hostile twin updates cannot stop a node; replay, record and node
processes stop and fail cleanly. Each test starts real ``hdphm`` processes in its own domain."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("rclpy")
from hd_bag import read_mission, write_mission  # noqa: E402
import hd_ros as ru  # noqa: E402
from tests.robustness.hostile_updates import HOSTILE_UPDATES  # noqa: E402

pytestmark = pytest.mark.ros
SRC = os.path.join(os.path.dirname(__file__), "..", "..", "src")


def _hdphm(*args, **kw):
    env = dict(os.environ, PYTHONPATH=os.path.abspath(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-m", "hdphm.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env, **kw)


class _Client:
    """A test participant: publishes on /hd/twin/update, listens to /hd/twin/state."""

    def __init__(self, domain_id):
        from rclpy.node import Node
        from std_msgs.msg import String

        self.ctx = ru.init_context(domain_id)
        self.node = Node("hostile_client", context=self.ctx)
        self.ex = ru.make_executor(self.ctx)
        self.ex.add_node(self.node)
        self.states: list[dict] = []
        self.pub = self.node.create_publisher(String, ru.TOPIC_TWIN_UPDATE, ru.qos("latched"))
        self.pub_state = self.node.create_publisher(String, ru.TOPIC_TWIN_STATE, ru.qos("stream"))
        self.node.create_subscription(String, ru.TOPIC_TWIN_STATE,
                                      lambda m: self.states.append(ru.parse_json_msg(m, "s", 16 << 20)), ru.qos("latched"))

    def spin(self, s, until=None):
        end = time.monotonic() + s
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.05)
            if until is not None and until():
                return True
        return until() if until else True

    def answers(self, name: str, timeout: float = 10.0) -> bool:
        from rcl_interfaces.srv import ListParameters

        cli = self.node.create_client(ListParameters, f"/{name}/list_parameters")
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                return False
            fut = cli.call_async(ListParameters.Request())
            end = time.monotonic() + timeout
            while time.monotonic() < end and not fut.done():
                self.ex.spin_once(timeout_sec=0.05)
            return fut.done() and fut.result() is not None
        finally:
            self.node.destroy_client(cli)

    def close(self):
        import rclpy

        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def test_every_hostile_update_leaves_all_four_stack_nodes_answering(domain_id):
    from std_msgs.msg import String

    proc = _hdphm("stack", "--domain-id", str(domain_id))
    c = _Client(domain_id)
    try:
        assert c.spin(30, lambda: bool(c.states)), "no twin state from hdphm stack"
        rev0 = c.states[-1]["revision"]
        for name, text, _ in HOSTILE_UPDATES:
            c.pub.publish(String(data=text))
            c.spin(0.3)
            assert proc.poll() is None, f"hdphm stack died on {name}"
        # a hostile *state* from a foreign participant reaches the onboard node too
        for bad in ('{"thresholds": {"A": 5}}', '{"model_dir": "/etc"}', '{"params": {"N": "x"}}', "[" * 100_000):
            c.pub_state.publish(String(data=bad))
            c.spin(0.2)
        # and hostile mission documents reach the onboard and prognostic nodes
        pub_m = c.node.create_publisher(String, ru.TOPIC_MISSION, ru.qos("latched"))
        for bad in ('{"gear_ratio": true}', '{"actuator_id": {"a": 1}}', '{"gear_ratio": "1e999"}',
                    '{"actuator_id": "../../etc", "mission_index": "x"}', "{" * 50_000):
            pub_m.publish(String(data=bad))
            c.spin(0.2)
        assert proc.poll() is None
        c.pub.publish(String(data='{"updated_by": "after-the-attack"}'))
        assert c.spin(20, lambda: c.states[-1].get("updated_by") == "after-the-attack"), c.states[-1]
        st = c.states[-1]
        assert st["revision"] == rev0 + 1  # no hostile update was applied
        assert len(ru.json_msg(st).data) < 100_000  # nothing oversize was republished
        assert proc.poll() is None
        for n in ("twin", "onboard", "prognostic", "ground"):
            assert c.answers(n), f"{n} does not answer after the hostile updates"
    finally:
        c.close()
        proc.send_signal(signal.SIGINT)
        try:
            log = proc.communicate(timeout=10)[0]
        except subprocess.TimeoutExpired:
            proc.kill()
            log = proc.communicate()[0]
    assert "Traceback" not in log, log[-3000:]
    assert log.count("twin update refused") >= len(HOSTILE_UPDATES) - 1, log[-3000:]


def test_twin_node_in_process_keeps_a_bounded_refusal_memory(domain_id):
    from std_msgs.msg import String

    from hdphm.stack import Stack

    st = Stack(domain_id, nodes=("twin",))
    try:
        tw = st.nodes["twin"]
        cb = next(s for s in tw.subscriptions if s.topic_name == ru.TOPIC_TWIN_UPDATE).callback
        big = '{"updated_by": "' + "y" * 2_000_000 + '", "k": %d}'
        for k in range(100):
            cb(String(data=big % k))
        cb(String(data='{"effects": 5}'))
        assert tw.n_refused == 101 and len(tw.refusals) <= 32
        assert sum(len(str(r)) for r in tw.refusals) < 32 * 400
        assert all(isinstance(k, bytes) and len(k) == 32 for k in tw._seen) and len(tw._seen) <= 256
        assert tw.refusals[-1]["field"] == "effects"
        # an exception that escapes a callback is contained and counted
        tw.state = None  # break the node on purpose
        cb(String(data='{"updated_by": "x"}'))
        assert tw.n_callback_errors == 1
    finally:
        st.close()


def test_replay_of_a_bag_with_damaged_metadata_prints_one_line(tmp_path, domain_id):
    from tests.bag.conftest import make_mission
    from tests.bag.hostile import records

    from hd_bag.mcapio import OP_METADATA

    p = tmp_path / "md.mcap"
    write_mission(p, make_mission())
    d = bytearray(p.read_bytes())
    off = next(o for o, op, _ in records(bytes(d)) if op == OP_METADATA)
    name_len = int.from_bytes(d[off + 9:off + 13], "little")
    d[off + 9 + 4 + name_len + 1] ^= 0x10
    p.write_bytes(bytes(d))
    proc = _hdphm("replay", str(p), "--wait-s", "0", "--domain-id", str(domain_id))
    out = proc.communicate(timeout=60)[0]
    assert proc.returncode == 2, out
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert "Traceback" not in out and len(lines) == 1, out
    assert "md.mcap" in lines[0] and "corrupt" in lines[0] and "byte" in lines[0]


def test_replay_wait_for_refuses_to_start_without_every_subscriber(tmp_path, domain_id):
    from tests.bag.conftest import make_mission

    p = tmp_path / "ok.mcap"
    write_mission(p, make_mission())
    t0 = time.monotonic()
    proc = _hdphm("replay", str(p), "--wait-s", "1.5", "--wait-for", "2", "--domain-id", str(domain_id))
    out = proc.communicate(timeout=60)[0]
    assert proc.returncode == 2 and "expected subscribers" in out and "not replaying" in out, out
    assert time.monotonic() - t0 < 30


def test_node_twin_stops_on_sigint_and_recorder_on_sigterm_promptly(tmp_path, domain_id):
    tw = _hdphm("node", "twin", "--domain-id", str(domain_id))
    c = _Client(domain_id)
    try:
        assert c.spin(30, lambda: bool(c.states)), "twin node did not start"
        t0 = time.monotonic()
        tw.send_signal(signal.SIGINT)
        tw.communicate(timeout=10)
        assert time.monotonic() - t0 < 2.0
        assert tw.returncode == 0
    finally:
        if tw.poll() is None:
            tw.kill()
        c.close()
    # recorder: SIGTERM while data flows at 1 kHz
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    out = tmp_path / "rec.mcap"
    rec = _hdphm("record", "--out", str(out), "--domain-id", str(domain_id))
    ctx = ru.init_context(domain_id)
    node = Node("flow", context=ctx)
    pub = node.create_publisher(JointState, ru.TOPIC_JOINT_STATES, ru.qos("sensor"))
    try:
        end = time.monotonic() + 30
        while time.monotonic() < end and pub.get_subscription_count() == 0:
            time.sleep(0.05)
        n = 0
        t_stop = time.monotonic() + 2.0
        while time.monotonic() < t_stop:
            m = JointState(name=["motor", "output"], position=[float(n), 0.0])
            pub.publish(m)
            n += 1
            time.sleep(0.001)
        from rclpy.duration import Duration

        pub.wait_for_all_acked(Duration(seconds=5.0))
        n_sent = n
        t0 = time.monotonic()
        rec.send_signal(signal.SIGTERM)
        while rec.poll() is None and time.monotonic() - t0 < 15:  # data keeps flowing during the stop
            pub.publish(JointState(name=["motor", "output"], position=[float(n), 0.0]))
            n += 1
            time.sleep(0.001)
        dt = time.monotonic() - t0
        log = rec.communicate(timeout=10)[0]
    finally:
        node.destroy_node()
        import rclpy

        rclpy.try_shutdown(context=ctx)
        if rec.poll() is None:
            rec.kill()
    assert dt < 2.0, f"recorder took {dt:.1f} s to stop: {log[-2000:]}"
    from hd_bag.reader import _scan  # noqa: F401
    from hd_bag.mcapio import McapScan, scan_mcap

    sc = McapScan()
    got = 0
    for blk in scan_mcap(out, sc):
        cid = next(c for c, ch in sc.channels.items() if ch.topic == ru.TOPIC_JOINT_STATES)
        got += int(np.sum(blk.channel == cid))
    assert sc.complete
    assert got >= n_sent, f"recorded {got} of the {n_sent} joint states acknowledged before SIGTERM"
