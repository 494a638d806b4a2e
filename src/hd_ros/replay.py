"""Replay runtime: publishes bags on the contract topics (+ ``/hd/mission``) from any rclpy node.

The payload bytes of the bag are published as they are, with their original header stamps; the
bag's ``hd_mission`` metadata goes on ``/hd/mission`` (latched) before each bag's samples. Needs
no stack node: ``hdphm replay`` runs it from a bare node, :func:`hdphm.stack.run_stack_on_bags`
from the stack's I/O node with an in-process pump.
"""

from __future__ import annotations

import contextlib
import os
import time
from typing import Iterable

import numpy as np

from hd_ros.topics import CONTRACT_TOPICS

class BagSource:
    """Contract messages of one bag as raw CDR payloads in log-time order (streamed chunk by chunk)."""

    def __init__(self, path: str | os.PathLike):
        from hd_bag.mcapio import McapScan, scan_mcap

        self.path = os.fspath(path)
        if not os.path.isfile(self.path):
            raise ValueError(f"{self.path}: no such bag file")
        self.scan = McapScan()
        self._it = scan_mcap(self.path, self.scan)
        self.meta: dict[str, str] | None = None

    def blocks(self) -> Iterable[tuple[list[str], np.ndarray, list[bytes]]]:
        """Yield (topics, log_time_ns, payloads) per chunk, sorted by log time; contract topics only."""
        from hd_bag.mcapio import McapFormatError
        
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
        from sensor_msgs.msg import JointState, Temperature
        from std_msgs.msg import String

        import hd_ros as ru

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
        #: never fills (:data:`hd_ros.qos.SENSOR_DEPTH`) and no publish is ever refused.
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
        import hd_ros as ru

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

