"""Record runtime: records stack topics to MCAP from any rclpy node (raw CDR, no decode).

``hdphm record`` runs it from a bare node; :class:`hdphm.stack.Stack` from its I/O node (with the
contract topics tapped from an in-process :class:`hd_ros.replay.Replayer`).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Iterable

import numpy as np

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
        import hd_ros as ru

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

        import hd_ros as ru

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
        import hd_ros as ru

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
        import hd_ros as ru

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
        import hd_ros as ru

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
        import hd_ros as ru

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
        import hd_ros as ru

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



def drain(ex, rec, quiet_spins: int = 3, max_s: float = 0.5) -> None:
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

