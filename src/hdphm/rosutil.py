"""Shared ROS 2 helpers for the hdphm stack: topic names, QoS, message codecs.

Only standard message types travel on the wire (no custom .msg packages can be
built from the wheels): ``sensor_msgs``, ``std_msgs``, ``diagnostic_msgs``.
Every topic of the stack is listed here with its QoS, so nodes, replay and the
recorder agree by construction; ``docs/INTERFACES.md`` is the human table of
the same facts.

Numeric streams of the stack (residuals, features, health) are
``std_msgs/msg/Float64MultiArray`` with a 2-D row-major layout: ``dim[0]``
(label ``"rows"``) counts rows (samples or windows), ``dim[1]`` has the
comma-separated column names as its label, so a row block is self-describing
(:func:`pack_table` / :func:`unpack_table`). Parameter-like state (twin,
mission metadata) is JSON in ``std_msgs/msg/String``, latched.

This module imports rclpy lazily inside functions where possible so that
``import hdphm.rosutil`` stays cheap for the CLI.
"""

from __future__ import annotations

import array
import contextlib
import importlib
import json
import os
import struct
from pathlib import Path
from typing import Any, Iterable

import numpy as np

# --------------------------------------------------------------------------
# topic names
# --------------------------------------------------------------------------
TOPIC_JOINT_STATES = "/hd/joint_states"
TOPIC_COMMAND = "/hd/command"
TOPIC_TEMPERATURE = "/hd/temperature"
CONTRACT_TOPICS = (TOPIC_JOINT_STATES, TOPIC_COMMAND, TOPIC_TEMPERATURE)
#: Mission metadata (the bag's ``hd_mission`` record) as JSON, latched; published by replay
#: (or a live actuator's driver) before the samples of a mission.
TOPIC_MISSION = "/hd/mission"
TOPIC_TWIN_STATE = "/hd/twin/state"
TOPIC_TWIN_UPDATE = "/hd/twin/update"
TOPIC_RESIDUALS = "/hd/onboard/residuals"
TOPIC_FEATURES = "/hd/onboard/features"
TOPIC_HEALTH = "/hd/prognostic/health"
TOPIC_GROUND_REPORT = "/hd/ground/report"
TOPIC_DIAGNOSTICS = "/diagnostics"

#: type strings as they appear in the ROS graph and in MCAP schema names
TYPE_JOINT_STATE = "sensor_msgs/msg/JointState"
TYPE_TEMPERATURE = "sensor_msgs/msg/Temperature"
TYPE_STRING = "std_msgs/msg/String"
TYPE_F64_ARRAY = "std_msgs/msg/Float64MultiArray"
TYPE_DIAG_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"

#: topic -> (type, qos key) for every topic the stack itself publishes or consumes.
STACK_TOPICS: dict[str, tuple[str, str]] = {
    TOPIC_JOINT_STATES: (TYPE_JOINT_STATE, "sensor"),
    TOPIC_COMMAND: (TYPE_JOINT_STATE, "sensor"),
    TOPIC_TEMPERATURE: (TYPE_TEMPERATURE, "sensor"),
    TOPIC_MISSION: (TYPE_STRING, "latched"),
    TOPIC_TWIN_STATE: (TYPE_STRING, "latched"),
    TOPIC_TWIN_UPDATE: (TYPE_STRING, "latched"),
    TOPIC_RESIDUALS: (TYPE_F64_ARRAY, "stream"),
    TOPIC_FEATURES: (TYPE_F64_ARRAY, "stream"),
    TOPIC_HEALTH: (TYPE_F64_ARRAY, "stream"),
    TOPIC_GROUND_REPORT: (TYPE_STRING, "latched"),
    TOPIC_DIAGNOSTICS: (TYPE_DIAG_ARRAY, "diagnostics"),
}

# --------------------------------------------------------------------------
# QoS
# --------------------------------------------------------------------------
#: History depth of sensor topics. Reliable + KEEP_ALL on both sides gives
#: flow control: a full reader history withholds acknowledgements, so
#: ``replay --rate max`` is throttled by the slowest subscriber instead of
#: losing samples.
SENSOR_DEPTH = 5000


def qos(kind: str):
    """The QoS profile of a topic class: ``sensor``, ``stream``, ``latched``, ``diagnostics``.

    - sensor: reliable, keep-all (bounded by the middleware's resource limits),
      volatile: contract topics; no sample lost at any replay rate.
    - stream: reliable, keep-last 1000, volatile: residual/feature/health blocks.
    - latched: reliable, keep-last 1, transient-local: twin state, updates, mission metadata.
    - diagnostics: reliable, keep-last 100, volatile (as diagnostic_updater).
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    if kind == "sensor":
        return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=SENSOR_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    if kind == "stream":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    if kind == "latched":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if kind == "diagnostics":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    raise ValueError(f"unknown QoS class {kind!r}; one of sensor, stream, latched, diagnostics")


def mission_sub_qos():
    """Subscription QoS of ``/hd/mission``: latched (compatible with the publisher's keep-last 1) but
    keep-last 16, so missions announced faster than a busy subscriber takes them are all delivered."""
    q = qos("latched")
    q.depth = 16
    return q


def topic_qos(topic: str):
    """QoS profile of a stack topic (unknown topics get ``stream``)."""
    return qos(STACK_TOPICS.get(topic, ("", "stream"))[1])


def offered_qos_yaml(profiles: Iterable[Any]) -> str:
    """``offered_qos_profiles`` channel metadata in the YAML form ``ros2 bag`` writes.

    ``profiles`` are rclpy ``QoSProfile`` objects (one per publisher). Enum
    values are the rmw integers (history 1 keep_last / 2 keep_all,
    reliability 1 reliable / 2 best_effort, durability 1 transient_local /
    2 volatile), durations as sec/nsec with the "infinite" sentinel.
    """
    out = []
    for p in profiles:
        def dur(d) -> str:
            ns = int(getattr(d, "nanoseconds", 0))
            if ns <= 0 or ns >= 2**63 - 1:
                return "    sec: 9223372036\n    nsec: 854775807"
            return f"    sec: {ns // 10**9}\n    nsec: {ns % 10**9}"

        out.append(
            f"- history: {int(p.history)}\n  depth: {int(p.depth)}\n  reliability: {int(p.reliability)}\n"
            f"  durability: {int(p.durability)}\n  deadline:\n{dur(p.deadline)}\n  lifespan:\n{dur(p.lifespan)}\n"
            f"  liveliness: {int(p.liveliness)}\n  liveliness_lease_duration:\n{dur(p.liveliness_lease_duration)}\n"
            f"  avoid_ros_namespace_conventions: false"
        )
    return "\n".join(out)


# --------------------------------------------------------------------------
# domains, contexts
# --------------------------------------------------------------------------
def init_context(domain_id: int | None = None, args: list[str] | None = None):
    """A fresh rclpy Context on ``domain_id`` (None: ``$ROS_DOMAIN_ID`` or 0).

    Discovery is limited to this host (``ROS_AUTOMATIC_DISCOVERY_RANGE``
    defaults to LOCALHOST here unless the user set it), so a test or a demo
    never talks to machines on the network.
    """
    import rclpy

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None and not (0 <= int(domain_id) <= 232):
        raise ValueError(f"ROS domain id {domain_id} outside 0..232")
    ctx = rclpy.Context()
    rclpy.init(args=args, context=ctx, domain_id=None if domain_id is None else int(domain_id))
    return ctx


def set_thread_realtime(priority: int) -> str:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority`` (1-99; 0: ``SCHED_OTHER``).

    Threads created afterwards by this thread inherit the policy (the
    middleware's receive threads, when called before the context's first
    node). Returns "" on success, else why it was not possible (no Linux, no
    CAP_SYS_NICE / RLIMIT_RTPRIO): the caller logs it and runs on, unprioritised.
    """
    priority = int(priority)
    if not 0 <= priority <= 99:
        raise ValueError(f"real-time priority {priority} outside 0..99")
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO is not available on this platform"
    try:
        if priority == 0:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        else:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as e:
        return f"SCHED_FIFO priority {priority} refused ({e.strerror}; needs CAP_SYS_NICE or an rtprio limit)"
    return ""


PUBLICATION_MODE_ENV = "RMW_FASTRTPS_PUBLICATION_MODE"


@contextlib.contextmanager
def publication_mode(mode: str | None):
    """Within the block, a context's first node is created with Fast DDS publication ``mode``.

    ``"ASYNCHRONOUS"``: a writer queues the sample and the middleware's own
    thread delivers it (GIL-free, beside the Python executor; the choice for
    max-rate replay); ``"SYNCHRONOUS"``: delivered in the publishing thread
    (lowest latency, rmw_fastrtps's default); None: leave as is. rmw_fastrtps
    reads ``$RMW_FASTRTPS_PUBLICATION_MODE`` when a context creates its
    participant (its first node), so create that node inside the block. A
    value the user exported wins.
    """
    if mode is not None and mode not in ("ASYNCHRONOUS", "SYNCHRONOUS", "AUTO"):
        raise ValueError(f"publication mode {mode!r}: one of ASYNCHRONOUS, SYNCHRONOUS, AUTO")
    if mode is None or PUBLICATION_MODE_ENV in os.environ:
        yield
        return
    os.environ[PUBLICATION_MODE_ENV] = mode
    try:
        yield
    finally:
        os.environ.pop(PUBLICATION_MODE_ENV, None)


#: executor kind of the stack: "single" (SingleThreadedExecutor, the default) or "events"
#: (rclpy's C++ EventsExecutor, experimental in Jazzy: no wait-set rebuild per wake; measured
#: 1.1-1.6x faster max-rate replay, but with it the prognostic node missed the last mission's
#: final window rows in a replay of two missions, so it is opt-in until that is understood).
#: $HDPHM_EXECUTOR overrides.
EXECUTOR = os.environ.get("HDPHM_EXECUTOR", "single")


def make_executor(context, kind: str | None = None):
    """An executor for ``context``: ``kind`` "events" (falls back to "single" when unavailable) or "single"."""
    kind = kind or EXECUTOR
    if kind not in ("events", "single"):
        raise ValueError(f"executor kind {kind!r}: one of 'events', 'single'")
    if kind == "events":
        try:
            from rclpy.experimental.events_executor import EventsExecutor

            return EventsExecutor(context=context)
        except ImportError:
            pass
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


#: Interface packages of the ROS distribution whose message modules may be imported to subscribe to a
#: topic (``pkg.msg`` of these packages only): a type name advertised on the graph or written in a bag
#: selects a class from this fixed set, it never names a module to import (issue 13: a participant
#: advertising ``evilpkg/msg/X`` would have made the recorder import ``evilpkg.msg``).
MESSAGE_PACKAGES = frozenset((
    "std_msgs", "sensor_msgs", "diagnostic_msgs", "geometry_msgs", "builtin_interfaces", "rcl_interfaces",
    "nav_msgs", "trajectory_msgs", "shape_msgs", "stereo_msgs", "visualization_msgs", "tf2_msgs",
    "action_msgs", "unique_identifier_msgs", "statistics_msgs", "rosgraph_msgs", "lifecycle_msgs",
    "type_description_interfaces", "service_msgs",
))
_NAME_RE = None


def message_class(type_name: str):
    """Message class from a type string ``pkg/msg/Name`` (or ``pkg/Name``) of a package in
    :data:`MESSAGE_PACKAGES`; ValueError for anything else (nothing is imported for it)."""
    import re

    global _NAME_RE
    if _NAME_RE is None:
        _NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,127}")
    parts = str(type_name).split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts) or parts[1] != "msg" or not _NAME_RE.fullmatch(parts[2]):
        raise ValueError(f"not a ROS message type name: {str(type_name)[:80]!r}")
    if parts[0] not in MESSAGE_PACKAGES:
        raise ValueError(f"message type {type_name!r} is not in the fixed table of interface packages "
                         f"(hdphm.rosutil.MESSAGE_PACKAGES); not imported")
    try:
        mod = importlib.import_module(f"{parts[0]}.msg")
        cls = getattr(mod, parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f"message type {type_name!r} is not installed in this environment") from None
    if not hasattr(cls, "_TYPE_SUPPORT") and not hasattr(type(cls), "_TYPE_SUPPORT"):
        raise ValueError(f"{type_name!r} is not a message class")
    return cls


_SHARE_DIRS: list[Path] | None = None


def _share_dirs() -> list[Path]:
    global _SHARE_DIRS
    if _SHARE_DIRS is None:
        import sys

        cands = [Path(sys.prefix) / "share"]
        cands += [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
        _SHARE_DIRS = [c for c in cands if c.is_dir()]
    return _SHARE_DIRS


def _msg_file(pkg: str, name: str) -> str:
    for d in _share_dirs():
        f = d / pkg / "msg" / f"{name}.msg"
        if f.is_file():
            return f.read_text()
    raise ValueError(f"no .msg definition found for {pkg}/msg/{name} under {', '.join(map(str, _share_dirs()))}")


_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
}


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type with its dependencies, as ``ros2 bag`` writes it.

    The main definition, then for every nested type a ``====`` separator line
    and ``MSG: pkg/Name`` followed by its definition (depth-first, each once).
    """
    parts = type_name.split("/")
    pkg, name = parts[0], parts[-1]
    seen: list[str] = []
    texts: dict[str, str] = {}

    def deps(p: str, text: str) -> list[str]:
        out = []
        for line in text.splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            tok = line.split()[0]
            base = tok.split("[", 1)[0].split("<=", 1)[0]
            if base in _PRIMITIVES or "=" in line.split(None, 1)[-1][:1]:
                continue
            if base == "Header":
                q = "std_msgs/Header"
            elif "/" in base:
                q = base.replace("/msg/", "/")
            else:
                q = f"{p}/{base}"
            out.append(q)
        return out

    def visit(q: str) -> None:
        if q in texts:
            return
        p, n = q.split("/")
        texts[q] = _msg_file(p, n)
        seen.append(q)
        for d in deps(p, texts[q]):
            visit(d)

    visit(f"{pkg}/{name}")
    main = texts[seen[0]]
    out = [main.rstrip("\n")]
    for q in seen[1:]:
        out.append("=" * 80 + f"\nMSG: {q}\n" + texts[q].rstrip("\n"))
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------
# fast CDR codec for JointState (the hot path: 1-20 kHz)
# --------------------------------------------------------------------------
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


#: caps of the live decoders (the same as the bag reader's: hd_bag.cdr.MAX_JOINTS, MAX_MESSAGE_BYTES)
MAX_JOINTS = 64
MAX_JOINTSTATE_BYTES = 64 << 10


class CdrError(ValueError):
    """A serialized message that does not decode as the expected type."""


def decode_joint_state(buf: bytes) -> tuple[int, str, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Decode a CDR (little-endian) ``sensor_msgs/msg/JointState``.

    Returns (stamp_ns, frame_id, names, position, velocity, effort), arrays
    float64. About 10x faster than the generic deserializer; raises
    :class:`CdrError` naming the problem for a malformed buffer.
    """
    try:
        if len(buf) < 16:
            raise CdrError(f"JointState message of {len(buf)} bytes is too short")
        if len(buf) > MAX_JOINTSTATE_BYTES:
            raise CdrError(f"JointState message of {len(buf)} bytes is above the cap of {MAX_JOINTSTATE_BYTES}")
        if buf[1] != 1:
            raise CdrError("JointState message is not little-endian CDR (encapsulation kind %d)" % buf[1])
        sec, nsec = _STAMP.unpack_from(buf, 4)
        p = 12
        (n,) = _U32.unpack_from(buf, p)
        p += 4
        frame = buf[p:p + n - 1].decode("utf-8", "replace") if n else ""
        p += n
        p = (p + 3) & ~3
        (cnt,) = _U32.unpack_from(buf, p)
        p += 4
        if cnt > MAX_JOINTS:
            raise CdrError(f"JointState with {cnt} names is above the cap of {MAX_JOINTS} joints")
        names = []
        for _ in range(cnt):
            p = (p + 3) & ~3
            (n,) = _U32.unpack_from(buf, p)
            p += 4
            names.append(buf[p:p + n - 1].decode("utf-8", "replace"))
            p += n
        arrs = []
        for _ in range(3):
            p = (p + 3) & ~3
            (cnt,) = _U32.unpack_from(buf, p)
            p += 4
            if cnt > MAX_JOINTS:
                raise CdrError(f"JointState array of {cnt} values is above the cap of {MAX_JOINTS} joints")
            if cnt:
                # doubles aligned to 8 relative to the start of the CDR body (after the 4-byte header)
                p = 4 + ((p - 4 + 7) & ~7)
                end = p + 8 * cnt
                if end > len(buf):
                    raise CdrError(f"JointState array of {cnt} doubles runs past the end of the buffer")
                arrs.append(np.frombuffer(buf, dtype="<f8", count=cnt, offset=p))
                p = end
            else:
                arrs.append(np.empty(0))
        return sec * 1_000_000_000 + nsec, frame, names, arrs[0], arrs[1], arrs[2]
    except struct.error as e:
        raise CdrError(f"truncated JointState message ({e})") from None


_LAYOUTS: dict[int, Any] = {}


def decode_joint_states(msgs: list[bytes]) -> tuple[np.ndarray, np.ndarray, str, list[str]]:
    """Decode a batch of CDR JointStates at once -> (stamps_ns (n,), V (n, 6), frame_id, problems).

    ``V`` columns: position[0:2], velocity[0:2], effort[0:2] (NaN where an
    array is shorter). Messages that share the byte layout of the first one
    of their length (``hd_bag.cdr``: same frame, names and array lengths) are
    decoded with one numpy step; the rest one by one with
    :func:`decode_joint_state`. Undecodable messages are left out and named in
    ``problems`` (stamps and rows of the others keep arrival order).
    """
    from hd_bag.cdr import decode_doubles, decode_stamps, match_layout, parse_jointstate_layout

    n = len(msgs)
    stamps = np.zeros(n, np.int64)
    V = np.full((n, 6), np.nan)
    ok = np.zeros(n, bool)
    problems: list[str] = []
    frame = ""
    lens = np.fromiter((len(m) for m in msgs), np.int64, n)
    for L in np.unique(lens).tolist():
        idx = np.flatnonzero(lens == L)
        lay = _LAYOUTS.get(L)
        first = msgs[int(idx[0])]
        if lay is None or not match_layout(np.frombuffer(first, np.uint8)[None, :], lay)[0]:
            lay = parse_jointstate_layout(first)
            if lay is not None:
                _LAYOUTS[L] = lay
        slow = idx
        if lay is not None and len(idx) > 1:
            rows = np.frombuffer(b"".join(msgs[i] for i in idx.tolist()), np.uint8).reshape(len(idx), L)
            good = match_layout(rows, lay)
            gi = idx[good]
            stamps[gi] = decode_stamps(rows[good])
            for c0, off, k in zip((0, 2, 4), lay.offsets, lay.counts):
                if k >= 1:
                    V[gi, c0:c0 + min(k, 2)] = decode_doubles(rows[good], off, min(k, 2))
            ok[gi] = True
            frame = frame or lay.frame_id
            slow = idx[~good]
        for i in slow.tolist():
            try:
                s_, fr, _, pos, vel, eff = decode_joint_state(msgs[i])
            except CdrError as e:
                problems.append(str(e))
                continue
            stamps[i] = s_
            for c0, arr in ((0, pos), (2, vel), (4, eff)):
                k = min(len(arr), 2)
                V[i, c0:c0 + k] = arr[:k]
            ok[i] = True
            frame = frame or fr
    if not ok.all():
        stamps, V = stamps[ok], V[ok]
    return stamps, V, frame, problems


def decode_temperature(buf: bytes) -> tuple[int, str, float]:
    """Decode a CDR ``sensor_msgs/msg/Temperature`` -> (stamp_ns, frame_id, degC)."""
    try:
        sec, nsec = _STAMP.unpack_from(buf, 4)
        (n,) = _U32.unpack_from(buf, 12)
        p = 16
        frame = buf[p:p + n - 1].decode("utf-8", "replace") if n else ""
        p += n
        p = 4 + ((p - 4 + 7) & ~7)
        (temp,) = struct.unpack_from("<d", buf, p)
        return sec * 1_000_000_000 + nsec, frame, temp
    except struct.error as e:
        raise CdrError(f"truncated Temperature message ({e})") from None


# --------------------------------------------------------------------------
# Float64MultiArray tables, JSON strings, stamps
# --------------------------------------------------------------------------
def pack_table(columns: list[str] | tuple[str, ...], rows: np.ndarray):
    """A ``std_msgs/msg/Float64MultiArray`` holding ``rows`` (n x k) with named columns."""
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    rows = np.asarray(rows, dtype=np.float64)
    if rows.ndim == 1:
        rows = rows[None, :]
    n, k = rows.shape
    if k != len(columns):
        raise ValueError(f"table has {k} columns but {len(columns)} names")
    m = Float64MultiArray()
    m.layout.dim = [MultiArrayDimension(label="rows", size=n, stride=n * k),
                    MultiArrayDimension(label=",".join(columns), size=k, stride=k)]
    m.layout.data_offset = 0
    m.data = array.array("d", np.ascontiguousarray(rows).tobytes())
    return m


def unpack_table(msg) -> tuple[list[str], np.ndarray]:
    """Inverse of :func:`pack_table`: (column names, rows n x k)."""
    dims = msg.layout.dim
    if len(dims) != 2:
        raise ValueError(f"Float64MultiArray table needs 2 layout dims, got {len(dims)}")
    cols = dims[1].label.split(",")
    data = np.asarray(msg.data, dtype=np.float64)
    n, k = int(dims[0].size), int(dims[1].size)
    if k != len(cols) or data.size != n * k:
        raise ValueError(f"Float64MultiArray table layout {n}x{k} does not match {data.size} values / {len(cols)} names")
    return cols, data.reshape(n, k)


def json_msg(obj: Any):
    """``std_msgs/msg/String`` carrying ``obj`` as JSON (NaN/inf written as null)."""
    from std_msgs.msg import String

    from hd_bag.jsonsafe import json_safe

    return String(data=json.dumps(json_safe(obj), sort_keys=True))


#: Caps of :func:`parse_json_msg` (mission metadata, reports; the twin state has its own, larger cap).
MAX_JSON_BYTES = 1 << 20
MAX_JSON_DEPTH = 8


def parse_json_msg(msg, what: str, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH) -> dict:
    """Decode a JSON ``std_msgs/String``; raises ValueError naming ``what`` when it is not a JSON object,
    is longer than ``max_bytes``, nests deeper than ``max_depth`` or holds NaN/Infinity."""
    from hd_twin.state import parse_json

    return parse_json(getattr(msg, "data", None), what, max_bytes, max_depth)


def contain_callbacks(node, diag_name: str | None = None) -> None:
    """Wrap every subscription and timer callback of ``node`` (call at the end of its ``__init__``, before
    it is added to an executor): an exception is logged, counted in ``node.n_callback_errors`` and
    reported on ``/diagnostics`` (ERROR, at most once a second), and the node goes on; one message can
    no longer take a node, or a whole ``hdphm stack``, down."""
    import time as _time
    import traceback

    node.n_callback_errors = 0
    node.last_callback_error = ""
    last = {"t": -1e9}
    name = diag_name or f"hdphm/{node.get_name()}"

    def wrap(fn, what):
        if getattr(fn, "_hdphm_contained", False):
            return fn

        def contained(*a, **k):
            try:
                return fn(*a, **k)
            except Exception as e:  # noqa: BLE001 - containment is the point
                node.n_callback_errors += 1
                text = f"{what} callback failed ({type(e).__name__}: {str(e)[:200]}); node continues"
                node.last_callback_error = text
                now = _time.monotonic()
                if now - last["t"] >= 1.0:
                    last["t"] = now
                    tb = traceback.extract_tb(e.__traceback__)
                    where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
                    node.get_logger().error(text + where + f" [{node.n_callback_errors} so far]")
                    pub = getattr(node, "pub_diag", None)
                    if pub is not None:
                        try:
                            from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

                            st = DiagnosticStatus(name=f"{name}/callbacks", level=DiagnosticStatus.ERROR,
                                                  message=text[:250], hardware_id=node.get_name())
                            st.values = [KeyValue(key="callback_errors", value=str(node.n_callback_errors))]
                            arr = DiagnosticArray(status=[st])
                            arr.header.stamp = node.get_clock().now().to_msg()
                            pub.publish(arr)
                        except Exception:  # noqa: BLE001 - reporting must not fail the containment
                            pass
                return None

        contained._hdphm_contained = True
        contained.__wrapped__ = fn
        return contained

    for sub in list(getattr(node, "subscriptions", [])):
        sub.callback = wrap(sub.callback, sub.topic_name)
    for tmr in list(getattr(node, "timers", [])):
        tmr.callback = wrap(tmr.callback, "timer")


def stamp_to_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int):
    from builtin_interfaces.msg import Time

    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def take_all(sub, first) -> list:
    """``first`` plus every message already queued on subscription ``sub``, in arrival order.

    rclpy's executor costs tens of microseconds per callback; taking the
    whole queue inside one callback makes 1-20 kHz topics affordable in
    Python (measured: ~45 k messages/s through publish + take on one core)
    and hands the core a block to process vectorised.
    """
    out = [first]
    h = sub.handle
    with h:
        while True:
            r = h.take_message(sub.msg_type, sub.raw)
            if r is None:
                break
            out.append(r[0])
    return out
