"""Contract bag writers: :func:`write_mission` (one call) and :class:`MissionWriter` (streaming).

Files are MCAP with the ROS 2 profile, CDR messages, ``ros2msg`` schemas with
their dependencies, ``offered_qos_profiles`` on every channel and the
``hd_mission`` metadata record (``../shared/CONTRACT.md``). Messages are
serialised in blocks with numpy (:mod:`hd_bag.cdr`) and written as chunks of at
most ``chunk_seconds`` of data; every chunk is flushed to disk when written, so
a recorder killed mid-run leaves a file whose complete chunks
:func:`hd_bag.read_mission` recovers.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Mapping

import numpy as np

from . import cdr
from .errors import BagError
from .mcapio import McapFileWriter, message_records
from .mission import (JOINT_SIGNALS, TEMPERATURE_FRAMES, TOPIC_COMMAND, TOPIC_JOINT_STATES, TOPIC_TEMPERATURE,
                      Mission, MissionMeta)

TOPIC_SIM_INTERNAL = "/sim/internal"
TOPIC_SIM_HEALTH = "/sim/health"
TOPIC_SIM_EFFECTS = "/sim/effects"
SIM_TOPICS = (TOPIC_SIM_INTERNAL, TOPIC_SIM_HEALTH, TOPIC_SIM_EFFECTS)

_INF_DURATION = "    sec: 9223372036\n    nsec: 854775807\n"


def qos_yaml(durability: str = "volatile", reliability: str = "reliable", depth: int = 0,
             history: str = "unknown") -> str:
    """The ``offered_qos_profiles`` YAML string as ``ros2 bag record`` (Jazzy) writes it."""
    return ("- history: " + history + "\n"
            f"  depth: {depth}\n"
            f"  reliability: {reliability}\n"
            f"  durability: {durability}\n"
            "  deadline:\n" + _INF_DURATION.replace("    ", "    ") +
            "  lifespan:\n" + _INF_DURATION +
            "  liveliness: automatic\n"
            "  liveliness_lease_duration:\n" + _INF_DURATION +
            "  avoid_ros_namespace_conventions: false")


QOS_SENSOR = qos_yaml("volatile")
QOS_LATCHED = qos_yaml("transient_local", depth=1, history="keep_last")

#: topic -> (type, latched)
TOPIC_TYPES = {
    TOPIC_JOINT_STATES: ("sensor_msgs/msg/JointState", False),
    TOPIC_COMMAND: ("sensor_msgs/msg/JointState", False),
    TOPIC_TEMPERATURE: ("sensor_msgs/msg/Temperature", False),
    TOPIC_SIM_INTERNAL: ("sensor_msgs/msg/JointState", False),
    TOPIC_SIM_HEALTH: ("sensor_msgs/msg/JointState", True),
    TOPIC_SIM_EFFECTS: ("std_msgs/msg/String", True),
}

JS_LAYOUT = cdr.jointstate_layout(("motor", "output"))
CMD_LAYOUT = cdr.jointstate_layout(("output",), counts=(1, 0, 0))


def _f64(name: str, x: Any, n: int) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if a.shape[0] != n:
        raise ValueError(f"{name}: {a.shape[0]} values for {n} stamps")
    return a


def _stamps(stamp_ns: Any) -> np.ndarray:
    s = np.asarray(stamp_ns)
    if s.dtype.kind == "f":
        if not np.all(np.isfinite(s)):
            raise ValueError("stamps must be finite")
        s = np.round(s).astype(np.int64)
    s = s.astype(np.int64).reshape(-1)
    if len(s) and s.min() < 0:
        raise ValueError("stamps must be >= 0 ns (ROS time)")
    return s


#: Operating hours above this are not an actuator's (114 years of continuous running).
MAX_OPERATING_HOURS = 1e6
#: mission_index above this is not a plausible life (10^7 missions).
MAX_MISSION_INDEX = 10_000_000
MAX_ID_LENGTH = 128


def safe_identifier(value: str, what: str = "actuator_id") -> str | None:
    """Why ``value`` cannot be used as a file name component (None when it can): identifiers end up in
    archive and recorder file names, so no path separators, no '..', no control characters."""
    v = str(value)
    if not v.strip():
        return f"{what} is empty"
    if len(v) > MAX_ID_LENGTH:
        return f"{what} is {len(v)} characters long (at most {MAX_ID_LENGTH})"
    if "/" in v or "\\" in v:
        return f"{what} = {v[:40]!r} contains a path separator"
    if ".." in v or v in (".",):
        return f"{what} = {v[:40]!r} contains '..' (not a safe file name)"
    if any(ord(c) < 32 or ord(c) == 127 for c in v):
        return f"{what} = {v[:40]!r} contains control characters"
    return None


def check_meta(meta: MissionMeta, where: str = "") -> list[str]:
    """Problems with a metadata record's values (empty when fine)."""
    p = []
    for k in ("operating_hours", "gear_ratio", "torque_constant"):
        v = getattr(meta, k)
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            p.append(f"{k} = {v!r} is not a finite number")
    if not p:
        if not 0 < meta.gear_ratio <= 10_000:
            p.append(f"gear_ratio = {meta.gear_ratio!r} is not physical (need 0 < N <= 10000)")
        if not 0 < meta.torque_constant <= 100:
            p.append(f"torque_constant = {meta.torque_constant!r} N*m/A is not physical (need 0 < k_t <= 100)")
        if meta.operating_hours < 0:
            p.append(f"operating_hours = {meta.operating_hours!r} is negative")
        elif meta.operating_hours > MAX_OPERATING_HOURS:
            p.append(f"operating_hours = {meta.operating_hours!r} is not plausible (> {MAX_OPERATING_HOURS:g} h)")
    if int(meta.mission_index) < 0:
        p.append(f"mission_index = {meta.mission_index!r} is negative")
    elif int(meta.mission_index) > MAX_MISSION_INDEX:
        p.append(f"mission_index = {meta.mission_index!r} is not plausible (> {MAX_MISSION_INDEX})")
    why = safe_identifier(meta.actuator_id)
    if why:
        p.append(why)
    if meta.source not in ("simulation", "test_bench", "flight"):
        p.append(f"source = {meta.source!r} (need simulation, test_bench or flight)")
    return p


class MissionWriter:
    """Streaming writer of one contract bag.

    >>> with MissionWriter("m.mcap", meta) as w:          # doctest: +SKIP
    ...     w.add_joint_states(stamp_ns, theta_m, theta_f, omega_m, omega_f, tau_m, Q_red)
    ...     w.add_command(stamp_ns, theta_ref)
    ...     w.add_temperature("gearbox", stamp_ns, T)

    Each ``add_*`` takes arrays (one element per message; stamps in ns since
    the epoch, ``header.stamp``); log time defaults to the stamp. Pending
    messages go to disk as one chunk whenever ``chunk_bytes`` or
    ``chunk_seconds`` (of log time) is exceeded, and on :meth:`flush` /
    :meth:`close`.
    """

    def __init__(self, path: str | os.PathLike, meta: MissionMeta, *, compression: str = "zstd",
                 chunk_bytes: int = 512 * 1024, chunk_seconds: float = 1.0, fsync: bool = False,
                 check: bool = True):
        if check:
            probs = check_meta(meta)
            if probs:
                raise BagError(path, "refusing to write absurd hd_mission metadata: " + "; ".join(probs))
        self.path = os.fspath(path)
        self.meta = meta
        self._w = McapFileWriter(self.path, compression=compression, fsync=fsync)
        self._w.add_metadata("hd_mission", meta.to_record())
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self._pending: list[tuple[int, np.ndarray, np.ndarray]] = []
        self._pending_bytes = 0
        self._pending_t0: int | None = None
        self.chunk_bytes = int(chunk_bytes)
        self.chunk_ns = int(chunk_seconds * 1e9)

    # ---- channels ---------------------------------------------------------
    def channel(self, topic: str, type_name: str | None = None, latched: bool | None = None,
                schema_text: str | None = None) -> int:
        """Channel id for ``topic`` (registered on first use)."""
        cid = self._channel_ids.get(topic)
        if cid is not None:
            return cid
        t_default, l_default = TOPIC_TYPES.get(topic, (None, False))
        type_name = cdr.normalise_type(type_name or t_default or "")
        if not type_name:
            raise ValueError(f"{topic}: message type needed for a non-contract topic")
        latched = l_default if latched is None else latched
        sid = self._schema_ids.get(type_name)
        if sid is None:
            text = schema_text if schema_text is not None else cdr.SCHEMAS.get(type_name)
            if text is None:
                raise ValueError(f"{type_name}: no schema text known; pass schema_text")
            sid = len(self._schema_ids) + 1
            self._w.add_schema(sid, type_name, "ros2msg", text.encode())
            self._schema_ids[type_name] = sid
        cid = len(self._channel_ids)
        self._w.add_channel(cid, sid, topic, "cdr", {"offered_qos_profiles": QOS_LATCHED if latched else QOS_SENSOR})
        self._channel_ids[topic] = cid
        return cid

    # ---- raw ----------------------------------------------------------------
    def add_rows(self, topic: str, payload: np.ndarray, log_time_ns: np.ndarray) -> None:
        """Add n serialised messages of equal length ((n, L) uint8) on ``topic``."""
        cid = self.channel(topic)
        n = len(payload)
        if n == 0:
            return
        lt = np.asarray(log_time_ns, np.uint64).reshape(-1)
        s0 = self._seq.get(cid, 0)
        seq = (s0 + np.arange(n, dtype=np.uint64)) % (1 << 32)
        self._seq[cid] = s0 + n
        rec = message_records(cid, seq, lt, lt, payload)
        self._pending.append((cid, lt, rec))
        self._pending_bytes += rec.nbytes
        t0 = int(lt.min())
        self._pending_t0 = t0 if self._pending_t0 is None else min(self._pending_t0, t0)
        if self._pending_bytes >= self.chunk_bytes or int(lt.max()) - self._pending_t0 >= self.chunk_ns:
            self.flush()

    def add_serialized(self, topic: str, data: bytes, log_time_ns: int, type_name: str | None = None,
                       schema_text: str | None = None, latched: bool | None = None) -> None:
        """Add one already-serialised CDR message (for recorders)."""
        self.channel(topic, type_name, latched, schema_text)
        self.add_rows(topic, np.frombuffer(data, np.uint8)[None, :], np.array([log_time_ns]))

    # ---- contract topics -------------------------------------------------------
    def add_joint_states(self, stamp_ns, theta_m, theta_f, omega_m, omega_f, tau_m, Q_red, log_time_ns=None) -> None:
        """/hd/joint_states: angles rad, speeds rad/s, tau_m and Q_red N*m."""
        s = _stamps(stamp_ns)
        n = len(s)
        v = [_f64(k, x, n) for k, x in zip(JOINT_SIGNALS, (theta_m, theta_f, omega_m, omega_f, tau_m, Q_red))]
        rows = cdr.encode_jointstate(JS_LAYOUT, s, np.stack(v[0:2], 1), np.stack(v[2:4], 1), np.stack(v[4:6], 1))
        self.add_rows(TOPIC_JOINT_STATES, rows, s if log_time_ns is None else log_time_ns)

    def add_command(self, stamp_ns, theta_ref, log_time_ns=None) -> None:
        """/hd/command: commanded output angle theta_ref, rad."""
        s = _stamps(stamp_ns)
        rows = cdr.encode_jointstate(CMD_LAYOUT, s, _f64("theta_ref", theta_ref, len(s))[:, None])
        self.add_rows(TOPIC_COMMAND, rows, s if log_time_ns is None else log_time_ns)

    def add_temperature(self, frame: str, stamp_ns, temperature, log_time_ns=None) -> None:
        """/hd/temperature: degrees Celsius of ``frame`` (motor_winding or gearbox)."""
        if frame not in TEMPERATURE_FRAMES:
            raise ValueError(f"temperature frame {frame!r} is not one of {TEMPERATURE_FRAMES}")
        s = _stamps(stamp_ns)
        rows = cdr.encode_temperature(frame, s, _f64(f"temperature[{frame}]", temperature, len(s)))
        self.add_rows(TOPIC_TEMPERATURE, rows, s if log_time_ns is None else log_time_ns)

    def add_named_values(self, topic: str, stamp_ns, values: Mapping[str, Any], log_time_ns=None) -> None:
        """A JointState whose ``name`` lists quantities and ``position`` their values (``/sim/...``)."""
        s = _stamps(stamp_ns)
        names = tuple(values)
        lay = cdr.jointstate_layout(names, counts=(len(names), 0, 0))
        pos = np.stack([_f64(f"{topic}:{k}", values[k], len(s)) for k in names], 1) if names else None
        self.add_rows(topic, cdr.encode_jointstate(lay, s, pos), s if log_time_ns is None else log_time_ns)

    def add_string(self, topic: str, stamp_ns: int, text: str, latched: bool | None = None) -> None:
        self.channel(topic, "std_msgs/msg/String", latched)
        self.add_rows(topic, np.frombuffer(cdr.encode_string(text), np.uint8)[None, :], np.array([stamp_ns]))

    # ---- lifecycle ---------------------------------------------------------------
    def flush(self) -> None:
        """Write pending messages as one chunk (time-sorted per channel) and flush the file."""
        if not self._pending:
            return
        by_c: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for cid, lt, rec in self._pending:
            by_c.setdefault(cid, []).append((lt, rec))
        blocks = []
        for cid, parts in by_c.items():
            widths = {r.shape[1] for _, r in parts}
            if len(widths) == 1:
                lt = np.concatenate([p[0] for p in parts])
                rec = np.concatenate([p[1] for p in parts])
                o = np.argsort(lt, kind="stable")
                blocks.append((cid, lt[o], rec[o]))
            else:  # mixed message lengths: interleave by log time as variable-length records
                lt = np.concatenate([p[0] for p in parts])
                recs = [r.tobytes() for _, rec in parts for r in rec]
                o = np.argsort(lt, kind="stable")
                blocks.append((cid, lt[o], [recs[i] for i in o.tolist()]))
        self._w.write_chunk(blocks)
        self._pending.clear()
        self._pending_bytes = 0
        self._pending_t0 = None

    def write_windowed(self, per_topic: list[tuple[str, np.ndarray, np.ndarray]], edges_ns: np.ndarray) -> None:
        """Batch path: (topic, log_time sorted, rows) blocks cut into chunks at ``edges_ns``."""
        self.flush()
        prepared = []
        for topic, lt, rows in per_topic:
            if len(lt) == 0:
                continue
            cid = self.channel(topic)
            lt = np.asarray(lt, np.uint64)
            if len(lt) > 1 and np.any(np.diff(lt.astype(np.int64)) < 0):
                o = np.argsort(lt, kind="stable")
                lt, rows = lt[o], rows[o]
            s0 = self._seq.get(cid, 0)
            seq = (s0 + np.arange(len(lt), dtype=np.uint64)) % (1 << 32)
            self._seq[cid] = s0 + len(lt)
            prepared.append((cid, lt, message_records(cid, seq, lt, lt, rows)))
        cuts = [np.searchsorted(lt, np.asarray(edges_ns, np.uint64), side="left") for _, lt, _ in prepared]
        for k in range(len(edges_ns) + 1):
            blocks = []
            for (cid, lt, rec), c in zip(prepared, cuts):
                a = 0 if k == 0 else c[k - 1]
                b = len(lt) if k == len(edges_ns) else c[k]
                if b > a:
                    blocks.append((cid, lt[a:b], rec[a:b]))
            self._w.write_chunk(blocks)

    def close(self) -> None:
        self.flush()
        self._w.close()

    def __enter__(self) -> "MissionWriter":
        return self

    def __exit__(self, et, ev, tb) -> None:
        if et is None:
            self.close()
        else:  # leave what was written readable, but no summary
            try:
                self.flush()
            finally:
                self._w.abort()


def _sim_part(sim: Mapping[str, Any], key: str):
    return sim.get(key, sim.get(f"/sim/{key}"))


def write_mission(path: str | os.PathLike, mission: Mission, *, sim: Mapping[str, Any] | None = None,
                  compression: str = "zstd", chunk_seconds: float = 1.0) -> str:
    """Write ``mission`` as a contract bag at ``path``; returns the path.

    ``sim`` (simulated bags only, evaluation ground truth): ``{"internal":
    {name: array on mission.t}, "health": {name: float}, "effects": dict or JSON
    string}`` (keys may also be the topic names ``/sim/internal`` ...).
    Stamps are ``mission.t0_ns + round(t * 1e9)``; log time = stamp.
    """
    path = os.fspath(path)
    n = mission.n
    t0 = int(mission.t0_ns)
    if n == 0:
        raise BagError(path, "refusing to write a mission with no joint-state samples")
    t = np.asarray(mission.t, np.float64)
    if not np.all(np.isfinite(t)):
        raise BagError(path, "mission.t has non-finite times")
    s_js = t0 + np.round(t * 1e9).astype(np.int64)
    v = [_f64(k, getattr(mission, k), n) for k in JOINT_SIGNALS]
    per_topic = [(TOPIC_JOINT_STATES, s_js,
                  cdr.encode_jointstate(JS_LAYOUT, s_js, np.stack(v[0:2], 1), np.stack(v[2:4], 1),
                                        np.stack(v[4:6], 1)))]
    if len(mission.t_cmd):
        s_c = t0 + np.round(np.asarray(mission.t_cmd, np.float64) * 1e9).astype(np.int64)
        per_topic.append((TOPIC_COMMAND, s_c, cdr.encode_jointstate(
            CMD_LAYOUT, s_c, _f64("theta_ref", mission.theta_ref, len(s_c))[:, None])))
    temp_parts = []
    for frame, (tt, vv) in mission.temperatures.items():
        if frame not in TEMPERATURE_FRAMES:
            raise BagError(path, f"temperature frame {frame!r} is not one of {TEMPERATURE_FRAMES}")
        s_t = t0 + np.round(np.asarray(tt, np.float64) * 1e9).astype(np.int64)
        temp_parts.append((s_t, cdr.encode_temperature(frame, s_t, _f64(f"temperature[{frame}]", vv, len(s_t)))))
    if temp_parts:
        # one topic, frames interleaved by time; rows of different frames differ in width
        widths = {r.shape[1] for _, r in temp_parts}
        if len(widths) == 1:
            s_t = np.concatenate([p[0] for p in temp_parts])
            rows = np.concatenate([p[1] for p in temp_parts])
            o = np.argsort(s_t, kind="stable")
            per_topic.append((TOPIC_TEMPERATURE, s_t[o], rows[o]))
        else:
            per_topic.extend((TOPIC_TEMPERATURE, s, r) for s, r in temp_parts)
    if sim:
        internal = _sim_part(sim, "internal")
        if internal:
            internal = dict(internal)
            ts = internal.pop("t", None)
            s_i = s_js if ts is None else t0 + np.round(np.asarray(ts, np.float64) * 1e9).astype(np.int64)
            names = tuple(internal)
            lay = cdr.jointstate_layout(names, counts=(len(names), 0, 0))
            pos = np.stack([_f64(f"/sim/internal:{k}", internal[k], len(s_i)) for k in names], 1)
            per_topic.append((TOPIC_SIM_INTERNAL, s_i, cdr.encode_jointstate(lay, s_i, pos)))
    with MissionWriter(path, mission.meta, compression=compression) as w:
        # channels in a fixed order: contract topics first
        for topic, _, _ in per_topic:
            w.channel(topic)
        if sim:
            health = _sim_part(sim, "health")
            if health:
                w.add_named_values(TOPIC_SIM_HEALTH, [t0], {k: [float(x)] for k, x in health.items()})
            effects = _sim_part(sim, "effects")
            if effects is not None:
                text = effects if isinstance(effects, str) else json.dumps(effects, default=_json_default)
                w.add_string(TOPIC_SIM_EFFECTS, t0, text)
            w.flush()
        span = s_js[-1] - s_js[0]
        step = max(int(chunk_seconds * 1e9), 1)
        edges = s_js[0] + step * np.arange(1, int(span // step) + 1, dtype=np.int64)
        w.write_windowed(per_topic, edges)
    return path


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
