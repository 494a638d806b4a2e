"""``hdphm node | stack | replay | record``: the running ROS 2 stack from the shell, plus its Python API.

* ``hdphm node onboard|prognostic|ground|twin [--ros-args -p name:=value ...]``
  runs one node; its parameters come from ``ros2_ws/config/<node>.yaml``
  (a standard ROS 2 params file) and then from ``--ros-args``, parsed by
  rclpy itself.
* ``hdphm stack`` runs all four nodes **in one process** on one
  executor (``rosutil.make_executor``: a SingleThreadedExecutor; rclpy's EventsExecutor with
  ``HDPHM_EXECUTOR=events``): Python nodes of this size share one core well,
  the latched twin state is delivered without discovery latency, and one
  process is simpler to supervise on an actuator computer. For isolation
  (a crashing ground analysis must not stop the onboard monitor) run
  ``hdphm node ...`` per process instead: the topics and QoS are the same.
* ``hdphm replay BAG... [--rate 1.0|max]`` publishes the contract topics
  with their original header stamps (the payload bytes of the bag are
  published as they are) and the bag's ``hd_mission`` metadata on
  ``/hd/mission`` before each bag.
* ``hdphm record --out FILE.mcap`` records every ``/hd/...``,
  ``/diagnostics`` and stack topic; chunks are flushed every
  ``--flush-s`` seconds, so a recorder killed mid-run leaves a readable
  file with everything before the last flush.

:func:`run_stack_on_bags` is the in-process API the demo uses: replay bags
through all four nodes with a recorder, lossless at any rate.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, Iterable

import numpy as np

NODES = ("onboard", "prognostic", "ground", "twin")
CONFIG_DIR = Path(__file__).resolve().parents[2] / "ros2_ws" / "config"


# --------------------------------------------------------------------------
# building nodes
# --------------------------------------------------------------------------
def make_node(name: str, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True):
    """Instantiate one of the four stack nodes by name (``param_services=False``: no ``ros2 param`` services,
    fewer entities for the executor to wait on; used by the in-process replay job). The nodes are managed
    (lifecycle) nodes: ``autostart`` configures and activates them at once; ``autostart=False`` leaves them
    unconfigured for a lifecycle manager (``hdphm.managed``)."""
    if name == "onboard":
        from hd_onboard.node import make_node as mk
    elif name == "twin":
        from hd_twin.node import make_node as mk
    elif name == "prognostic":
        from hd_prognostic.node import make_node as mk
    elif name == "ground":
        from hd_ground.node import make_node as mk
    else:
        raise ValueError(f"unknown node {name!r}; one of {', '.join(NODES)}")
    return mk(context=context, overrides=overrides, param_services=param_services, autostart=autostart)


def ros_args_for(name: str, extra: list[str] | None) -> list[str]:
    """rclpy args: the node's YAML params file (if present) then the user's ``--ros-args`` tail."""
    args = ["hdphm"]
    cfg = CONFIG_DIR / f"{name}.yaml"
    if cfg.is_file():
        args += ["--ros-args", "--params-file", str(cfg)]
    if extra:
        if extra[0] != "--ros-args":
            extra = ["--ros-args"] + extra
        args += extra
    return args


# --------------------------------------------------------------------------
# replay
# --------------------------------------------------------------------------
class BagSource:
    """Contract messages of one bag as raw CDR payloads in log-time order (streamed chunk by chunk)."""

    def __init__(self, path: str | os.PathLike):
        from hd_bag.mcapio import McapFormatError, McapScan, scan_mcap  # noqa: F401

        self.path = os.fspath(path)
        if not os.path.isfile(self.path):
            raise ValueError(f"{self.path}: no such bag file")
        self.scan = McapScan()
        self._it = scan_mcap(self.path, self.scan)
        self.meta: dict[str, str] | None = None

    def blocks(self) -> Iterable[tuple[list[str], np.ndarray, list[bytes]]]:
        """Yield (topics, log_time_ns, payloads) per chunk, sorted by log time; contract topics only."""
        from hd_bag.mcapio import McapFormatError
        from hdphm.rosutil import CONTRACT_TOPICS

        try:
            for blk in self._it:
                if self.meta is None:
                    self.meta = self.scan.metadata.get("hd_mission")
                    if self.meta is None:  # other tools write metadata after the chunks: look ahead once
                        from hd_bag import read_metadata

                        self.meta = read_metadata(self.path).get("hd_mission")
                chans = self.scan.channels
                topic_of = {cid: c.topic for cid, c in chans.items()}
                sel = np.array([topic_of.get(int(c)) in CONTRACT_TOPICS for c in blk.channel], bool)
                if not sel.any():
                    continue
                idx = np.flatnonzero(sel)
                idx = idx[np.argsort(blk.log_time[idx], kind="stable")]
                b = blk.buf
                pay = [b[s:s + n].tobytes() for s, n in zip(blk.start[idx].tolist(), blk.length[idx].tolist())]
                yield [topic_of[int(c)] for c in blk.channel[idx]], blk.log_time[idx].astype(np.int64), pay
        except McapFormatError as e:
            raise ValueError(f"{self.path}: {e}") from None
        if self.meta is None:
            self.meta = self.scan.metadata.get("hd_mission")


#: s a cross-process replay waits for every reader to acknowledge a mission's samples before the next
#: ``/hd/mission`` (a loaded machine took more than 2 s: samples were filed with the next mission)
ACK_TIMEOUT_S = 30.0


class Replayer:
    """Publishes bags on the contract topics (+ ``/hd/mission``) from an rclpy node.

    ``rate``: a float (1.0 = real time, by log time) or ``"max"``.
    ``pump`` (in-process use) is called after every ``batch`` messages to let
    the subscribers in the same executor drain (lossless max-rate replay;
    with ``drained`` it is called until they have taken everything);
    across processes the reliable keep-all QoS provides the back-pressure (a
    publish the middleware refuses because a reader's history is full is
    retried after a pause, see :meth:`_publish`).
    """

    def __init__(self, node, rate: float | str = 1.0, batch: int = 500, pump=None, tap=None, drained=None):
        from rclpy.qos import QoSProfile  # noqa: F401
        from sensor_msgs.msg import JointState, Temperature
        from std_msgs.msg import String

        from hdphm import rosutil as ru

        self.node = node
        self.rate = rate if rate == "max" else float(rate)
        if self.rate != "max" and not (0 < self.rate < 1e4):
            raise ValueError(f"replay rate {rate!r} must be > 0 (or 'max')")
        self.batch = int(batch)
        if self.batch < 1:
            raise ValueError(f"replay batch {batch!r} must be >= 1")
        self.pump = pump
        #: ``drained()`` (in-process use, with ``pump``): True once the consumers have taken every message
        #: published so far. With it, a max-rate replay pumps after each batch until the consumers caught up
        #: (one executor pass per ready callback instead of a fixed number of passes), so a reader history
        #: never fills (:data:`hdphm.rosutil.SENSOR_DEPTH`) and no publish is ever refused.
        self.drained = drained
        self.tap = tap  # tap(topic, [payloads]): an in-process recorder files what is published
        self.pubs = {
            ru.TOPIC_JOINT_STATES: node.create_publisher(JointState, ru.TOPIC_JOINT_STATES, ru.qos("sensor")),
            ru.TOPIC_COMMAND: node.create_publisher(JointState, ru.TOPIC_COMMAND, ru.qos("sensor")),
            ru.TOPIC_TEMPERATURE: node.create_publisher(Temperature, ru.TOPIC_TEMPERATURE, ru.qos("sensor")),
        }
        self.pub_mission = node.create_publisher(String, ru.TOPIC_MISSION, ru.qos("latched"))
        self.counts = {t: 0 for t in self.pubs}
        self.n_mission = 0
        self.sample_seconds = 0.0

    def _flush_tap(self, tapped) -> None:
        if tapped:
            for t, pays in tapped.items():
                if pays:
                    self.tap(t, pays)
                    tapped[t] = []

    def _publish(self, topic: str, pay: bytes) -> None:
        """Publish; when the middleware refuses (reliable keep-all history full: the readers have not
        taken yet), let them drain and retry, so max-rate replay throttles instead of failing."""
        try:
            self.pubs[topic].publish(pay)
            return
        except Exception as e:  # noqa: BLE001 - rclpy raises RCLError (not importable by a stable name)
            err = e
        for k in range(200):
            if self.pump:
                self.pump(force=True)
            else:  # another process's reader is full: give it time to take
                time.sleep(min(0.001 * (k + 1), 0.05))
            try:
                self.pubs[topic].publish(pay)
                return
            except Exception as e:  # noqa: BLE001
                err = e
        raise RuntimeError(f"replay: publishing on {topic} keeps failing ({err})")

    def _catch_up(self, limit_s: float = 10.0) -> None:
        """After a batch: let in-process consumers take what was published (until ``drained()``, if given)."""
        if not self.pump:
            return
        self.pump()
        if self.drained is None:
            return
        end = None
        while not self.drained():
            if end is None:
                end = time.monotonic() + limit_s
            elif time.monotonic() > end:  # a consumer stopped taking: go on, the counts will show it
                return
            self.pump()

    def _play_block_max(self, topics, lt, pays, skip, counts, tapped, since_pump: int) -> int:
        """Max-rate publishing of one chunk's messages, in log-time order: payload bytes straight to the
        publisher handles (no per-message wrapper), counted, tapped and pumped per ``batch``."""
        n = len(pays)
        a = 0
        handles = {t: p.handle for t, p in self.pubs.items()}
        while a < n:
            b = min(n, a + self.batch - since_pump)
            with contextlib.ExitStack() as es:  # keep the handles alive while their raw methods are called
                for h in handles.values():
                    es.enter_context(h)
                for k in range(a, b):
                    topic = topics[k]
                    if topic in skip:
                        continue
                    try:
                        handles[topic].publish_raw(pays[k])
                    except Exception:  # noqa: BLE001 - refused (reader history full): drain and retry
                        self._publish(topic, pays[k])
                    counts[topic] += 1
                    self.counts[topic] += 1
                    if tapped is not None:
                        tapped[topic].append(pays[k])
            since_pump += b - a
            a = b
            if since_pump >= self.batch:
                since_pump = 0
                self._flush_tap(tapped)
                self._catch_up()
        return since_pump

    def play(self, path, skip_topics: Iterable[str] = (), transform=None) -> dict:
        """Replay one bag; returns per-topic counts. ``transform(topic, log_ns, payload)`` may edit or drop (None)."""
        from hdphm import rosutil as ru

        src = BagSource(path)
        skip = set(skip_topics)
        t_wall0 = None
        t_log0 = None
        counts = {t: 0 for t in self.pubs}
        sent_meta = False
        since_pump = 0
        first_ns = last_ns = None
        tapped = {t: [] for t in self.pubs} if self.tap is not None else None
        # in-process max-rate replay: raw handles, batches; across processes the per-message path (whose pace
        # the remote readers' acknowledgements keep up with; the raw path lost commands in a remote recorder)
        fast = self.rate == "max" and transform is None and self.pump is not None
        for topics, lt, pays in src.blocks():
            if not sent_meta:
                if self.pump is None and self.n_mission:
                    from rclpy.duration import Duration

                    for p in self.pubs.values():  # the previous mission's samples reached every reader
                        if not p.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S)):
                            self.node.get_logger().warning(
                                f"replay: {p.topic_name} not acknowledged by every reader within {ACK_TIMEOUT_S:g} s; "
                                "a per-mission recorder may file its last samples with the next mission")
                meta = dict(src.meta or {})
                meta.setdefault("bag", str(path))
                mmsg = ru.json_msg(meta)
                self.pub_mission.publish(mmsg)
                if self.tap is not None:
                    from rclpy.serialization import serialize_message

                    self.tap(ru.TOPIC_MISSION, [serialize_message(mmsg)])
                self.n_mission += 1
                sent_meta = True
                if self.pump is None:  # across processes: the mission is known before its samples
                    from rclpy.duration import Duration

                    self.pub_mission.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
                if self.pump:
                    self.pump(force=True)
                    self._catch_up()
            if fast:
                since_pump = self._play_block_max(topics, lt, pays, skip, counts, tapped, since_pump)
                if len(lt):
                    first_ns = int(lt[0]) if first_ns is None else first_ns
                    last_ns = int(lt[-1])
                continue
            for topic, ln, pay in zip(topics, lt.tolist(), pays):
                if topic in skip:
                    continue
                if transform is not None:
                    r = transform(topic, ln, pay)
                    if r is None:
                        continue
                    pay = r
                if self.rate != "max":
                    if t_wall0 is None:
                        t_wall0, t_log0 = time.monotonic(), ln
                    delay = (ln - t_log0) * 1e-9 / self.rate - (time.monotonic() - t_wall0)
                    if delay > 0:
                        if self.pump:
                            self.pump(timeout=delay)
                        else:
                            time.sleep(delay)
                self._publish(topic, pay)
                if tapped is not None:
                    tapped[topic].append(pay)
                counts[topic] += 1
                self.counts[topic] += 1
                first_ns = ln if first_ns is None else first_ns
                last_ns = ln
                since_pump += 1
                if since_pump >= self.batch:
                    since_pump = 0
                    self._flush_tap(tapped)
                    self._catch_up()
        self._flush_tap(tapped)
        if not sent_meta:
            raise ValueError(f"{path}: no contract messages to replay")
        if self.pump:
            self.pump(force=True)
            self._catch_up()
        if first_ns is not None:
            self.sample_seconds += (last_ns - first_ns) * 1e-9
        return counts


# --------------------------------------------------------------------------
# recorder
# --------------------------------------------------------------------------
def _src_ts(info) -> int:
    """Publisher source timestamp [ns] from an rclpy MessageInfo (dict in Jazzy)."""
    try:
        return int(info["source_timestamp"])
    except (TypeError, KeyError):
        return int(getattr(info, "source_timestamp", 0))


class Recorder:
    """Records topics to MCAP from an rclpy node (raw CDR, no decode).

    Subscribes at once to every known stack topic and, every ``discover_s``,
    to any other topic under ``/hd/`` or ``/diagnostics`` that appears. Each
    channel's ``offered_qos_profiles`` is taken from the publishers found on
    the graph at its first message; the subscription QoS is adapted like
    ``ros2 bag`` does (best effort if any publisher is best effort,
    transient-local if all publishers are). The first ``/hd/mission`` message
    becomes the file's ``hd_mission`` metadata record.

    One file (default) is a **stack log**: with several missions in it, the
    contract topics of different missions (often with overlapping stamps)
    share one channel, so it is not a contract bag of one mission (``hdphm
    validate`` judges it as one mission and its ``hd_mission`` record names
    the first only). ``split_per_mission=True`` makes ``out`` a directory
    and starts a new file ``<actuator_id>_m<mission_index>.mcap`` at every
    ``/hd/mission`` message: each file is a contract bag of one mission
    (its own ``hd_mission`` metadata) plus the stack topics received during
    it, and begins with the last message of every latched topic (twin state,
    ground report) so it stands alone. The ``/hd/mission`` queue is drained
    before every contract-topic message is filed, so samples of a new mission
    never land in the previous file (the replayer waits until its mission
    message is acknowledged before publishing the samples).
    """

    LATCHED_KEEP = ("/hd/twin/state", "/hd/twin/update", "/hd/ground/report")

    def __init__(self, node, out: str | os.PathLike, prefixes=("/hd/", "/diagnostics"), flush_s: float = 0.5,
                 discover_s: float = 0.25, compression: str = "zstd", split_per_mission: bool = False,
                 tapped: Iterable[str] = ()):
        from hdphm import rosutil as ru

        self.node = node
        self.out = os.fspath(out)
        self.split = bool(split_per_mission)
        self.compression = compression
        if self.split:
            if os.path.isfile(self.out):
                raise ValueError(f"{self.out}: --split-per-mission needs a directory, this is a file")
            Path(self.out).mkdir(parents=True, exist_ok=True)
        else:
            Path(self.out).parent.mkdir(parents=True, exist_ok=True)
        self.prefixes = tuple(prefixes)
        self.subs: dict[str, Any] = {}
        self.types: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.pending: list[tuple[int, int, bytes]] = []
        self.files: list[str] = []
        self.latched: dict[str, bytes] = {}
        self.flush_s = float(flush_s)
        self._last_flush = time.monotonic()
        self.closed = False
        self.w = None
        if not self.split:
            self._open(self.out)
        self.tapped = set(tapped)  # topics filed by tap() (an in-process replayer), not subscribed
        for topic, (typ, _) in ru.STACK_TOPICS.items():
            if topic in self.tapped:
                self.types[topic] = typ
                self.counts[topic] = 0
                self.subs[topic] = None
                continue
            self._subscribe(topic, typ)
        self.timer = node.create_timer(discover_s, self._discover)
        self.flush_timer = node.create_timer(self.flush_s, self._maybe_flush)

    def _open(self, path: str) -> None:
        from hd_bag.mcapio import McapFileWriter

        self.w = McapFileWriter(path, compression=self.compression, library="hdphm record")
        self.path = path
        self.files.append(path)
        self.channels: dict[str, int] = {}
        self.schemas: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self.meta_written = False

    def _wanted(self, topic: str) -> bool:
        return any(topic == p or topic.startswith(p) for p in self.prefixes)

    def _subscribe(self, topic: str, typ: str, pub_qos=None) -> None:
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

        from hdphm import rosutil as ru

        if topic in self.subs or not self._wanted(topic):
            return
        try:
            cls = ru.message_class(typ)
        except ValueError as e:
            self.node.get_logger().warning(f"record: skipping {topic}: {e}")
            return
        q = ru.mission_sub_qos() if topic == ru.TOPIC_MISSION else ru.topic_qos(topic)
        if pub_qos:
            if any(p.reliability == ReliabilityPolicy.BEST_EFFORT for p in pub_qos):
                q.reliability = ReliabilityPolicy.BEST_EFFORT
            if all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in pub_qos):
                q.durability = DurabilityPolicy.TRANSIENT_LOCAL
        self.types[topic] = typ
        self.counts[topic] = 0
        sub_holder = {}
        contract = topic in ru.CONTRACT_TOPICS

        if topic == ru.TOPIC_MISSION and self.split:
            def cb(first, info):  # noqa: ANN001
                self._mission_msg(first, _src_ts(info))
                self._poll_mission()
        elif contract and self.split:
            def cb(first, info):  # noqa: ANN001 - (message, MessageInfo): routed by source timestamp
                self._on_contract(topic, sub_holder["s"], first, _src_ts(info))
        else:
            def cb(first, topic=topic):
                msgs = ru.take_all(sub_holder["s"], first)
                self._on_msgs(topic, msgs, time.time_ns())

        sub_holder["s"] = self.node.create_subscription(cls, topic, cb, q, raw=True)
        self.subs[topic] = sub_holder["s"]

    @staticmethod
    def _take_with_src(sub) -> list[tuple[bytes, int]]:
        out = []
        with sub.handle:
            while True:
                r = sub.handle.take_message(sub.msg_type, sub.raw)
                if r is None:
                    break
                out.append((r[0], _src_ts(r[1])))
        return out

    def _on_contract(self, topic: str, sub, first: bytes, first_src: int) -> None:
        """Split mode: file contract messages by the publisher's source timestamp against the
        ``/hd/mission`` boundaries, so a sample published before a mission message goes to the
        previous file even when the readers deliver the two topics in another order."""
        from hdphm import rosutil as ru

        # take everything this topic has queued first: a mission boundary below takes the queued
        # messages of every contract topic, and would otherwise file ours ahead of ``first``
        held = [(first, first_src)] + self._take_with_src(sub)
        msub = self.subs.get(ru.TOPIC_MISSION)
        if msub is not None:
            for mmsg, msrc in self._take_with_src(msub):
                self._file_src(topic, [h for h in held if h[1] < msrc])
                held = [h for h in held if h[1] >= msrc]
                self._mission_msg(mmsg, msrc)
        self._file_src(topic, held + self._take_with_src(sub))

    def _file_src(self, topic: str, items: list[tuple[bytes, int]]) -> None:
        if items:
            self._on_msgs(topic, [m for m, _ in items], time.time_ns())

    def _mission_msg(self, mmsg: bytes, msrc: int) -> None:
        """A mission boundary: contract messages already queued and published before it go to the
        current file, then the new file starts; later ones are filed there."""
        from hdphm import rosutil as ru

        later: dict[str, list[tuple[bytes, int]]] = {}
        for t in ru.CONTRACT_TOPICS:
            sub = self.subs.get(t)
            if sub is None:
                continue
            items = self._take_with_src(sub)
            self._file_src(t, [x for x in items if x[1] < msrc])
            later[t] = [x for x in items if x[1] >= msrc]
        self._on_msgs(ru.TOPIC_MISSION, [mmsg], time.time_ns())
        for t, items in later.items():
            self._file_src(t, items)

    def _poll_mission(self) -> None:
        """Split mode (mission topic subscribed): handle every delivered ``/hd/mission`` message."""
        from hdphm import rosutil as ru

        sub = self.subs.get(ru.TOPIC_MISSION)
        if sub is None:  # not subscribed (tapped): in order by construction
            return
        for mmsg, msrc in self._take_with_src(sub):
            self._mission_msg(mmsg, msrc)

    def _discover(self) -> None:
        for topic, types in self.node.get_topic_names_and_types():
            if topic not in self.subs and self._wanted(topic) and types:
                infos = self.node.get_publishers_info_by_topic(topic)
                self._subscribe(topic, types[0], [i.qos_profile for i in infos])

    def _channel(self, topic: str) -> int:
        from hdphm import rosutil as ru

        cid = self.channels.get(topic)
        if cid is not None:
            return cid
        typ = self.types[topic]
        sid = self.schemas.get(typ)
        if sid is None:
            sid = len(self.schemas) + 1
            self.w.add_schema(sid, typ, "ros2msg", ru.message_definition(typ).encode())
            self.schemas[typ] = sid
        infos = self.node.get_publishers_info_by_topic(topic)
        profiles = [i.qos_profile for i in infos] or [ru.topic_qos(topic)]
        cid = len(self.channels)
        self.w.add_channel(cid, sid, topic, "cdr", {"offered_qos_profiles": ru.offered_qos_yaml(profiles)})
        self.channels[topic] = cid
        return cid

    @staticmethod
    def _meta_of(payload: bytes) -> dict | None:
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import String

        try:
            meta = json.loads(deserialize_message(payload, String).data)
            return meta if isinstance(meta, dict) else None
        except (ValueError, TypeError):
            return None

    def _rotate(self, meta: dict) -> None:
        """Close the current file and start the file of the mission ``meta``."""
        self.flush()
        if self.w is not None:
            self.w.close()
        act = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(meta.get("actuator_id", "unknown")))
        try:
            mi = int(float(meta.get("mission_index", 0)))
        except (TypeError, ValueError):
            mi = 0
        base = os.path.join(self.out, f"{act}_m{mi:04d}")
        path, k = base + ".mcap", 1
        while os.path.exists(path) or path in self.files:
            k += 1
            path = f"{base}_{k}.mcap"
        pend = self.pending
        self.pending = []
        self._open(path)
        now = time.time_ns()
        for topic, pay in self.latched.items():  # the file stands alone: latched state first
            self.pending.append((self._channel(topic), now, pay))
        # what arrived before the first mission (no file open yet) belongs to the first file
        self.pending += [(self._channel(t), lt, m) for t, lt, m in pend] if pend and isinstance(pend[0][0], str) else []

    def _on_msgs(self, topic: str, msgs: list[bytes], now_ns: int) -> None:
        if self.closed:
            return
        from hdphm import rosutil as ru

        self.counts[topic] += len(msgs)
        if topic == ru.TOPIC_MISSION:
            for m in msgs:
                meta = self._meta_of(m)
                if meta is None:
                    self.node.get_logger().warning("record: /hd/mission is not JSON; no hd_mission metadata written")
                elif self.split:
                    self._rotate(meta)
                self._file(topic, now_ns, m)
                if meta is not None and not self.meta_written:
                    self.w.add_metadata("hd_mission", {k: str(v) for k, v in meta.items() if k != "bag"})
                    self.meta_written = True
            return
        if topic in self.LATCHED_KEEP and msgs:
            self.latched[topic] = msgs[-1]
        if self.w is None:
            self.pending.extend((topic, now_ns, m) for m in msgs)
        else:
            cid = self._channel(topic)
            self.pending.extend((cid, now_ns, m) for m in msgs)
        if len(self.pending) >= 20000:
            self.flush()

    def tap(self, topic: str, payloads: list[bytes]) -> None:
        """File messages published by a replayer in this process, as published (see :class:`Replayer`)."""
        self._on_msgs(topic, payloads, time.time_ns())

    def _file(self, topic: str, now_ns: int, m: bytes) -> None:
        if self.w is None:  # split mode before the first mission: keep by topic name
            self.pending.append((topic, now_ns, m))
        else:
            self.pending.append((self._channel(topic), now_ns, m))

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        """Write everything pending as one chunk (the file stays readable if the process dies after this)."""
        from hd_bag.mcapio import message_records

        self._last_flush = time.monotonic()
        if not self.pending or self.closed or self.w is None:
            return
        pend, self.pending = self.pending, []
        seq = self._seq
        by_len: dict[tuple[int, int], list[tuple[int, bytes]]] = {}
        for cid, lt, m in pend:
            by_len.setdefault((cid, len(m)), []).append((lt, m))
        blocks = []
        for (cid, L), items in by_len.items():
            n = len(items)
            lt = np.array([i[0] for i in items], np.uint64)
            pay = np.frombuffer(b"".join(i[1] for i in items), np.uint8).reshape(n, L)
            s0 = seq.get(cid, 0)
            seq[cid] = s0 + n
            sq = (s0 + np.arange(n, dtype=np.uint64)) % (1 << 32)
            blocks.append((cid, lt, message_records(cid, sq, lt, lt, pay)))
        self.w.write_chunk(blocks)

    def close(self) -> None:
        if self.closed:
            return
        if self.w is None and self.pending:  # split mode, no mission ever announced
            pend = self.pending
            self.pending = []
            self._open(os.path.join(self.out, "no_mission.mcap"))
            self.pending = [(self._channel(t), lt, m) for t, lt, m in pend]
        self.flush()
        self.closed = True
        if self.w is not None:
            self.w.close()


# --------------------------------------------------------------------------
# in-process stack
# --------------------------------------------------------------------------
class Stack:
    """All four nodes (+ optional replayer/recorder node) in one process, one executor."""

    def __init__(self, domain_id: int | None = None, overrides: dict[str, dict[str, Any]] | None = None,
                 nodes: Iterable[str] = NODES, record: str | None = None, args: list[str] | None = None,
                 split_per_mission: bool = False, tap_replay: bool = False, param_services: bool = True,
                 publication_mode: str | None = None):
        """``tap_replay``: the recorder files the contract topics and ``/hd/mission`` from an in-process
        :class:`Replayer` (``Replayer(..., tap=stack.recorder.tap)``) instead of subscribing to them.
        ``publication_mode``: Fast DDS publication mode of this stack's writers
        (:func:`hdphm.rosutil.publication_mode`; None: the middleware default, synchronous)."""
        from rclpy.node import Node

        from hdphm import rosutil as ru

        self.param_services = bool(param_services)
        self.nodes: dict[str, Any] = {}
        overrides = overrides or {}
        with ru.publication_mode(publication_mode):  # read when the context's first node creates the participant
            self.ctx = ru.init_context(domain_id, args)
            self.ex = ru.make_executor(self.ctx)
            self.aux = Node("hdphm_stack_io", context=self.ctx, start_parameter_services=self.param_services)
        for name in nodes:
            self.add(name, overrides.get(name))
        self.ex.add_node(self.aux)
        self.recorder = (Recorder(self.aux, record, split_per_mission=split_per_mission,
                                  tapped=(ru.TOPIC_MISSION,) + ru.CONTRACT_TOPICS if tap_replay else ())
                         if record else None)

    def add(self, name: str, overrides: dict[str, Any] | None = None):
        node = make_node(name, self.ctx, overrides, self.param_services)
        self.nodes[name] = node
        self.ex.add_node(node)
        return node

    def remove(self, name: str) -> None:
        node = self.nodes.pop(name)
        self.ex.remove_node(node)
        node.destroy_node()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def pump(self, timeout: float = 0.0, force: bool = False) -> None:
        """Let every subscriber take what was published (lossless in-process replay)."""
        end = time.monotonic() + timeout
        n = 0
        while True:
            self.ex.spin_once(timeout_sec=0.0)
            n += 1
            if n >= (12 if force else 3) and time.monotonic() >= end:
                break
            if time.monotonic() < end:
                self.ex.spin_once(timeout_sec=min(0.005, max(0.0, end - time.monotonic())))

    def close(self) -> None:
        if self.recorder:
            self.pump(force=True)
            self.recorder.close()
        for n in list(self.nodes.values()) + [self.aux]:
            try:
                self.ex.remove_node(n)
                n.destroy_node()
            except Exception:  # noqa: BLE001
                pass
        self.ex.shutdown()
        try:
            import rclpy

            rclpy.shutdown(context=self.ctx)
        except Exception:  # noqa: BLE001
            pass


def run_stack_on_bags(bags: list[str | os.PathLike], model_dir: str | None = None, out_mcap: str | None = None,
                      rate: float | str = "max", domain_id: int | None = None,
                      overrides: dict[str, dict[str, Any]] | None = None, settle_s: float = 0.5,
                      progress: bool = True, obs_model: str | None = None, split_per_mission: bool = False,
                      archive_dir: str | None = None, replay_batch: int = 500, async_publish: bool = False) -> dict:
    """Replay ``bags`` (in the given order) through twin, onboard, prognostic and ground nodes in one process.

    ``model_dir``: trained twin (ONNX) for the twin core and the onboard node
    (None: physics-only stand-in); ``obs_model``: the prognostic node's
    observation model JSON; ``archive_dir``: mission archive the ground node
    analyses at start (its thresholds/parameters reach the onboard node
    through the twin core before the replay starts);
    ``split_per_mission``: ``out_mcap`` is a directory with one contract
    bag per mission (see :class:`Recorder`); ``replay_batch``: contract
    messages published between two executor pumps at ``rate="max"`` (the
    replay then pumps until the onboard node has taken all of them, so it
    must stay well below the reader history, ``rosutil.SENSOR_DEPTH``);
    ``async_publish``: the stack's writers use Fast DDS asynchronous
    publication (delivery in the middleware's thread; order per topic and
    reliability unchanged; the replay waits at every mission boundary until
    the onboard node has taken the mission message and every sample before
    it). Off by default: ``hdphm bench replay`` measured it slower on 2 cores
    (the delivery thread competes with the executor for the same cores).

    Returns a summary: per-topic counts published and recorded, flags
    (actuator, stamp, level, reason), per-actuator last health / RUL and the
    final row of every mission, the wall time and the replay speed-up over
    real time.
    """
    from hdphm import rosutil as ru

    overrides = {k: dict(v) for k, v in (overrides or {}).items()}
    if model_dir:
        overrides.setdefault("twin", {})["model_dir"] = str(model_dir)
        overrides.setdefault("onboard", {})["model_dir"] = str(model_dir)
    if obs_model:
        overrides.setdefault("prognostic", {})["obs_model"] = str(obs_model)
    if archive_dir:
        overrides.setdefault("ground", {})["archive_dir"] = str(archive_dir)
    st = Stack(domain_id, overrides, record=out_mcap, split_per_mission=split_per_mission, tap_replay=True,
               param_services=False, publication_mode="ASYNCHRONOUS" if async_publish else None)
    try:
        st.spin_for(settle_s)  # latched twin state reaches the onboard node
        if archive_dir:  # the ground analysis runs in a worker thread; wait for its update to be applied
            gr, tw = st.nodes["ground"], st.nodes["twin"]
            end = time.monotonic() + 300.0
            while time.monotonic() < end and gr.n_runs == 0 and gr.error is None:
                st.spin_for(0.1)
            if gr.error:
                raise ValueError(f"ground analysis of {archive_dir} failed: {gr.error}")
            st.spin_for(0.3)
        def drained() -> bool:  # the onboard node took every contract message published so far
            onb_ = st.nodes.get("onboard")
            taken = getattr(onb_, "n_taken", None)
            return taken is None or (all(taken.get(t, 0) >= n for t, n in rep.counts.items())
                                     and onb_.n_mission_msgs >= rep.n_mission)

        rep = Replayer(st.aux, rate, pump=st.pump, tap=st.recorder.tap if st.recorder else None, batch=replay_batch,
                       drained=drained)
        # the replay's publishers are new: wait until DDS discovery has matched the onboard
        # subscription, or a max-speed replay on a loaded machine loses its first samples
        end = time.monotonic() + 15.0
        while time.monotonic() < end and rep.pubs[ru.TOPIC_JOINT_STATES].get_subscription_count() == 0:
            st.ex.spin_once(timeout_sec=0.02)
        t0 = time.perf_counter()
        it = bags
        if progress:
            from tqdm import tqdm

            it = tqdm(bags, desc="replay", unit="bag", file=sys.stderr)
        for b in it:
            rep.play(b)
        st.pump(force=True)
        onb = st.nodes["onboard"]
        onb.close_mission()  # end of the replay ends the last mission (live: the stale timeout does it)
        st.pump(force=True)
        wall = time.perf_counter() - t0
        st.spin_for(0.3)
        prog = st.nodes.get("prognostic")
        summary = {
            "bags": [str(b) for b in bags],
            "published": dict(rep.counts),
            "received_onboard": dict(onb.n_msgs),
            "onboard_published": dict(onb.n_published),
            "flags": [{"actuator": a, "stamp_s": s * 1e-9, "level": int(lv), "reason": why} for a, s, lv, why in onb.flags],
            "n_warn": sum(1 for f in onb.flags if f[2] == 1),
            "n_error": sum(1 for f in onb.flags if f[2] == 2),
            "errors": list(onb.errors),
            "health": dict(getattr(prog, "last", {}) or {}),
            "health_history": {a: list(v) for a, v in (getattr(prog, "history", {}) or {}).items()},
            "ground_runs": getattr(st.nodes.get("ground"), "n_runs", 0),
            "wall_s": wall,
            "sample_s": rep.sample_seconds,
            "speedup": rep.sample_seconds / wall if wall > 0 else float("nan"),
            "twin": onb.core.expected.kind,
        }
        if st.recorder:
            st.pump(force=True)
            st.recorder.flush()
            summary["recorded"] = dict(st.recorder.counts)
            summary["out_mcap"] = st.recorder.out
            summary["recorded_files"] = list(st.recorder.files)
        return summary
    finally:
        st.close()


# --------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------
def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


def _pop_domain(args) -> None:
    """argparse REMAINDER also takes options written after the node name: move ``--domain-id N`` (and, for
    ``hdphm node``, ``--rt-priority N``) out."""
    ra = list(args.ros_args or [])
    end = ra.index("--ros-args") if "--ros-args" in ra else len(ra)
    head, tail = ra[:end], ra[end:]
    if hasattr(args, "managed") and "--managed" in head:
        args.managed = True
        head.remove("--managed")
    opts = ("--domain-id", "--rt-priority") if hasattr(args, "rt_priority") else ("--domain-id",)
    for opt in opts:
        for k, tok in enumerate(head):
            if tok == opt or tok.startswith(opt + "="):
                val = tok.split("=", 1)[1] if "=" in tok else (head[k + 1] if k + 1 < len(head) else None)
                if val is None or not val.lstrip("-").isdigit():
                    raise SystemExit(f"hdphm: {opt} needs an integer, got {val!r}")
                if opt == "--rt-priority" and not 0 <= int(val) <= 99:
                    raise SystemExit(f"hdphm: --rt-priority {val} outside 0..99")
                setattr(args, opt[2:].replace("-", "_"), int(val))
                del head[k:k + (1 if "=" in tok else 2)]
                break
    if head:
        raise SystemExit(f"hdphm: unexpected arguments {head}; node parameters go after --ros-args")
    args.ros_args = tail


def _stop_on_signals() -> dict:
    """SIGINT and SIGTERM set ``stop["v"]`` (Python handlers, installed after rclpy's): the spin loops below
    poll it every 0.1 s, so a node, the stack or the recorder stops promptly on Ctrl-C or SIGTERM (rclpy's
    own handler left a node without timers, the twin, blocked in its wait set)."""
    stop = {"v": False, "sig": None}

    def on_sig(signum, _frame):
        stop["v"] = True
        stop["sig"] = signum

    signal.signal(signal.SIGINT, on_sig)
    signal.signal(signal.SIGTERM, on_sig)
    return stop


def _spin_until_stopped(ex, stop: dict, end: float | None = None) -> None:
    while not stop["v"] and (end is None or time.monotonic() < end):
        ex.spin_once(timeout_sec=0.1)


def cmd_node(args) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from hdphm import rosutil as ru

    _pop_domain(args)
    if args.rt_priority:
        # before the context: the middleware's receive threads inherit SCHED_FIFO (measured: the onboard
        # node's p99 arrival -> flag latency follows the receive threads' scheduling on a loaded machine)
        why = ru.set_thread_realtime(args.rt_priority)
        print(f"hdphm node: {'SCHED_FIFO priority %d' % args.rt_priority if not why else 'not real-time: ' + why}",
              file=sys.stderr)
    ctx = ru.init_context(args.domain_id, ros_args_for(args.name, args.ros_args))
    # handlers before the node exists: a signal that comes while it configures (it may already publish)
    # stops the loop below at once instead of raising KeyboardInterrupt
    stop = _stop_on_signals()
    node = make_node(args.name, ctx, autostart=not args.managed)
    if args.managed:
        print(f"hdphm node: {args.name} is unconfigured, waiting for a lifecycle manager "
              f"(services /{node.get_name()}/change_state, /{node.get_name()}/get_state)", file=sys.stderr)
    ex = ru.make_executor(ctx)
    ex.add_node(node)
    try:
        _spin_until_stopped(ex, stop)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return 0


def cmd_stack(args) -> int:
    from rclpy.parameter import Parameter  # noqa: F401

    _pop_domain(args)
    argv = ["hdphm"]
    for n in NODES:
        cfg = CONFIG_DIR / f"{n}.yaml"
        if cfg.is_file():
            argv += ["--ros-args", "--params-file", str(cfg)]
    if args.ros_args:
        argv += args.ros_args if args.ros_args[0] == "--ros-args" else ["--ros-args"] + args.ros_args
    st = Stack(args.domain_id, record=args.record, args=argv)
    print(f"hdphm stack: nodes {', '.join(st.nodes)} in one process (domain {args.domain_id or os.environ.get('ROS_DOMAIN_ID', 0)}); Ctrl-C stops",
          file=sys.stderr)
    stop = _stop_on_signals()
    try:
        _spin_until_stopped(st.ex, stop)
    except KeyboardInterrupt:
        pass
    finally:
        st.close()
    return 0


def cmd_replay(args) -> int:
    from rclpy.node import Node

    from hdphm import rosutil as ru

    rate = "max" if args.rate == "max" else float(args.rate)
    for b in args.bags:  # a bag that cannot be opened fails before any waiting or publishing: one line
        try:
            from hd_bag import read_metadata

            read_metadata(b)
            next(iter(BagSource(b).blocks()), None)
        except (ValueError, OSError) as e:
            line = str(e).splitlines()[0] if str(e) else type(e).__name__
            print(f"hdphm replay: {line if line.startswith(str(b)) else f'{b}: {line}'}", file=sys.stderr)
            return 2
    ctx = ru.init_context(args.domain_id)
    node = Node("hdphm_replay", context=ctx)
    rep = Replayer(node, rate)
    # every expected reader (e.g. the stack and a recorder: --wait-for 2) on every contract topic and on
    # /hd/mission before the first sample: starting when the first one matched cost a recorder 0.5 s
    want = max(int(args.wait_for), 1)
    pubs = list(rep.pubs.values()) + [rep.pub_mission]
    deadline = time.monotonic() + args.wait_s
    while time.monotonic() < deadline and min(p.get_subscription_count() for p in pubs) < want:
        time.sleep(0.05)
    have = min(p.get_subscription_count() for p in pubs)
    if have < want:
        print(f"hdphm replay: only {have} of {want} expected subscribers on every topic after {args.wait_s:g} s "
              f"({', '.join(f'{p.topic_name} {p.get_subscription_count()}' for p in pubs)})"
              + ("; not replaying (--wait-for)" if args.wait_for else "; replaying anyway"), file=sys.stderr)
        if args.wait_for:
            node.destroy_node()
            import rclpy

            rclpy.try_shutdown(context=ctx)
            return 2
    t0 = time.perf_counter()
    try:
        for b in args.bags:
            c = rep.play(b)
            print(f"{b}: " + ", ".join(f"{k} {v}" for k, v in c.items()), file=sys.stderr)
        for p in rep.pubs.values():
            p.wait_for_all_acked()
    except (ValueError, OSError) as e:  # a bad bag: one line naming the file, no traceback
        print(f"hdphm replay: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
        return 2
    finally:
        wall = time.perf_counter() - t0
        node.destroy_node()
        import rclpy

        rclpy.try_shutdown(context=ctx)
    print(f"replayed {rep.sample_seconds:.1f} s of data in {wall:.2f} s ({rep.sample_seconds / max(wall, 1e-9):.1f}x real time)",
          file=sys.stderr)
    return 0


def _drain(ex, rec, quiet_spins: int = 3, max_s: float = 0.5) -> None:
    """On stop: file what the middleware already delivered to the recorder's readers (keep spinning
    until ``quiet_spins`` spins in a row record nothing, at most ``max_s``), so a SIGTERM loses no
    message that arrived before it."""
    end = time.monotonic() + max_s
    quiet, last = 0, -1
    while quiet < quiet_spins and time.monotonic() < end:
        try:
            ex.spin_once(timeout_sec=0.05)
        except (Exception, KeyboardInterrupt):  # noqa: BLE001 - shut down / second Ctrl-C: close what we have
            return
        n = sum(rec.counts.values())
        quiet = quiet + 1 if n == last else 0
        last = n


def cmd_record(args) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from hdphm import rosutil as ru

    ctx = ru.init_context(args.domain_id)
    node = Node("hdphm_record", context=ctx)
    try:
        rec = Recorder(node, args.out, flush_s=args.flush_s, split_per_mission=args.split_per_mission)
    except ValueError as e:
        print(f"hdphm record: {e}", file=sys.stderr)
        return 2
    ex = ru.make_executor(ctx)
    ex.add_node(node)
    stop = _stop_on_signals()  # SIGINT too: rclpy's handler shut the context down before the drain
    end = time.monotonic() + args.duration if args.duration else None
    try:
        while not stop["v"] and (end is None or time.monotonic() < end):
            ex.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        pass
    finally:
        t_stop = time.monotonic()
        _drain(ex, rec)
        rec.close()
        t_closed = time.monotonic()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    print(f"stopped: drained and closed in {t_closed - t_stop:.2f} s, shut down in {time.monotonic() - t_closed:.2f} s",
          file=sys.stderr)
    print(f"recorded {sum(rec.counts.values())} messages to {len(rec.files)} file(s) under {args.out}: "
          + ", ".join(f"{k} {v}" for k, v in rec.counts.items() if v), file=sys.stderr)
    return 0


def _cmd_onboard_eval(args) -> int:
    from hd_onboard.evaluate import cmd_eval

    return cmd_eval(args)


def _cmd_onboard_study(args) -> int:
    from hdphm.onboard_study import run_study

    return run_study(args)


def register(sub) -> None:
    p = sub.add_parser("onboard", help="onboard detector tools (eval: false-alarm rate over healthy bags)")
    osub = p.add_subparsers(dest="onboard_command", metavar="ONBOARDCOMMAND")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    pe = osub.add_parser("eval", help="false alarms of the onboard detector over healthy mission bags")
    pe.add_argument("paths", nargs="+", help="bags or directories of bags (all taken as healthy)")
    pe.add_argument("--ground", type=int, default=0,
                    help="calibrate lines on the first K missions per actuator and score the others (0: self-calibrated)")
    pe.add_argument("--model-dir", default="", help="trained twin (ONNX); default: physics-only stand-in")
    pe.add_argument("--out", default="", help="write onboard_eval.json and onboard_eval.png here")
    pe.add_argument("--quiet", action="store_true")
    pe.set_defaults(func=_cmd_onboard_eval)
    ps = osub.add_parser("study", help="detection delay per fault and severity on simulated faults + false alarms")
    from hd_onboard.study_args import add_study_args

    add_study_args(ps)
    ps.set_defaults(func=_cmd_onboard_study)

    p = sub.add_parser("node", help="run one stack node (onboard, prognostic, ground, twin)")
    p.add_argument("name", choices=NODES)
    p.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default $ROS_DOMAIN_ID)")
    p.add_argument("--rt-priority", type=int, default=0, choices=range(0, 100), metavar="0-99",
                   help="run the process SCHED_FIFO at this priority (middleware receive threads included; "
                        "worker threads stay normal); needs CAP_SYS_NICE; 0: normal scheduling")
    p.add_argument("--managed", action="store_true",
                   help="leave the node unconfigured: a lifecycle manager configures and activates it through "
                        "/NODE/change_state (default: configure and activate at start)")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args -p name:=value ...")
    p.set_defaults(func=cmd_node, fast_exit=True)

    p = sub.add_parser("stack", help="run all four nodes in one process")
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--record", default=None, help="also record to this MCAP file")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args -p onboard.param:=value ...")
    p.set_defaults(func=cmd_stack, fast_exit=True)

    p = sub.add_parser("replay", help="publish bags on the contract topics with their original stamps")
    p.add_argument("bags", nargs="+")
    p.add_argument("--rate", default="1.0", help="1.0 = real time, 'max' = as fast as the subscribers take it")
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--wait-s", type=float, default=5.0, help="wait this long for the subscribers before starting")
    p.add_argument("--wait-for", type=int, default=0, metavar="N",
                   help="start only when N subscribers (e.g. 2: the stack and a recorder) match every contract "
                        "topic and /hd/mission; exit 2 if they do not within --wait-s (0: wait for one, then "
                        "start anyway)")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("record", help="record /hd/..., /diagnostics and stack topics to MCAP")
    p.add_argument("--out", required=True)
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--flush-s", type=float, default=0.5, help="chunk flush period (data at risk on a kill)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C/SIGTERM)")
    p.add_argument("--split-per-mission", action="store_true",
                   help="--out is a directory; one contract bag per /hd/mission (default: one stack log file)")
    p.set_defaults(func=cmd_record, fast_exit=True)
