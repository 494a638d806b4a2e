"""Foreign-style contract bags: written by other tools, with effects our own writer never makes.

A CLI-free generator (usable from tests, notebooks and ``python -m
tests.robustness.foreign OUT``) of small contract bags (``../shared/CONTRACT.md``)
that no ``hd_bag`` writer touches:

* physics from the plant simulator (``hd_sim.simulate_mission``: realistic
  signals, no ``/sim/...`` ground truth is written), then
* **written** with plain ``mcap-ros2-support`` (``mcap_ros2.writer.Writer``;
  chunked or unchunked, zstd / lz4 / none) or with ``rosbags``
  (``rosbags.rosbag2.Writer``, MCAP storage plugin: a ``ros2 bag``-style
  directory with ``metadata.yaml``, schemas and channels inside the first
  chunk, sequence numbers 0, the ``hd_mission`` record in the data section and
  not in the summary's metadata index), one Python message at a time,
* after a **variation** of the streams (:data:`VARIANTS`): sample rate, stamp
  jitter, duplicated / out-of-order stamps, dropouts, no torque sensor, no
  temperature, 1 Hz gearbox temperature, other gear ratio and k_t, one-sided
  / constant-speed / standstill motion, very short missions, large unwrapped
  theta_m, extra unrelated topics (``/tf``, ``/rosout``).

Each variant says what a correct stack must do with it (``expect``: ``"ok"``
or ``"error"`` plus a substring of the required message). Units: SI, stamps
in ns since the epoch.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

T0_NS = 1_750_000_000_123_456_789  # an arbitrary wall-clock epoch stamp (not a round number)

# Minimal message definitions of the extra topics (as `ros2 bag` would store them).
_TF_MSGDEF = """geometry_msgs/TransformStamped[] transforms
================================================================================
MSG: geometry_msgs/TransformStamped
std_msgs/Header header
string child_frame_id
Transform transform
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Transform
Vector3 translation
Quaternion rotation
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""
_LOG_MSGDEF = """byte DEBUG=10
byte INFO=20
byte WARN=30
byte ERROR=40
byte FATAL=50
builtin_interfaces/Time stamp
uint8 level
string name
string msg
string file
string function
uint32 line
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


@dataclass
class Streams:
    """What goes into one bag: per-topic stamps (ns) and values, plus the ``hd_mission`` record."""

    meta: dict[str, str]
    js_stamp: np.ndarray  # (n,) int64 ns, header.stamp, in file (arrival) order
    js: np.ndarray  # (n, 6): theta_m, theta_f, omega_m, omega_f, tau_m, Q_red
    cmd_stamp: np.ndarray
    theta_ref: np.ndarray
    temps: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)  # (frame_id, stamps, degC)
    extra_topics: bool = False  # /tf and /rosout messages, to be ignored by every reader
    joint_names: tuple[str, str] = ("motor", "output")


def simulate(*, seed: int = 0, duration: float = 2.0, fs: float = 1000.0, gear_ratio: int | None = None,
             k_t: float | None = None, profile: str = "inspection", health: dict | None = None):
    """A realistic mission from the plant simulator (the physics), as a :class:`hd_bag.Mission`.

    ``gear_ratio`` sets Z_CS = 2 N, Z_FS = 2 N - 2 (so N = Z_CS / (Z_CS - Z_FS)).
    """
    from hd_sim import simulate_mission
    from hd_sim.effects import EffectSet
    from hd_sim.params import nominal

    p = nominal()
    if gear_ratio is not None:
        p["Z_CS"], p["Z_FS"] = 2.0 * gear_ratio, 2.0 * gear_ratio - 2.0
    if k_t is not None:
        p["k_t"] = float(k_t)
    n_sub = max(1, int(round(40 * 1000.0 / fs)))
    m, _truth = simulate_mission(p, EffectSet.default(), profile, seed, duration=duration, fs=fs, n_sub=n_sub,
                                 health=health)
    return m


def streams_from_mission(m, *, actuator_id: str = "FX-0001", mission_index: int = 0,
                         operating_hours: float = 0.0, source: str = "test_bench") -> Streams:
    """The contract streams of a :class:`Mission` (no ``/sim`` truth), with a fresh metadata record."""
    n = m.n
    st = T0_NS + np.rint(m.t * 1e9).astype(np.int64)
    js = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    cst = T0_NS + np.rint(m.t_cmd * 1e9).astype(np.int64)
    temps = [(fr, T0_NS + np.rint(tt * 1e9).astype(np.int64), vv) for fr, (tt, vv) in m.temperatures.items()]
    meta = {"contract": "1", "actuator_id": actuator_id, "mission_index": str(int(mission_index)),
            "operating_hours": f"{operating_hours:.3f}", "gear_ratio": f"{m.meta.gear_ratio:g}",
            "torque_constant": f"{m.meta.torque_constant:g}", "source": source, "recorder": "foreign-rig-logger 3.2"}
    assert js.shape == (n, 6)
    return Streams(meta, st, js, cst, np.asarray(m.theta_ref, float).copy(), temps)


# ---------------------------------------------------------------------------
# writers (no hd_bag code involved)
# ---------------------------------------------------------------------------
def _hdr(stamp_ns: int, frame_id: str = "") -> dict:
    return {"stamp": {"sec": int(stamp_ns // 10**9), "nanosec": int(stamp_ns % 10**9)}, "frame_id": frame_id}


def _js_dict(stamp_ns: int, row: np.ndarray, names) -> dict:
    a = [float(x) for x in row]
    return {"header": _hdr(stamp_ns), "name": list(names), "position": a[0:2], "velocity": a[2:4],
            "effort": a[4:6]}


def _events(s: Streams):
    """(log_time_ns, kind, i) of every message, log time = stamp + a small transport delay."""
    # joint states are logged in arrival (file) order even when their stamps are not monotonic
    js_lt = np.maximum.accumulate(s.js_stamp) + 200_000 + np.arange(len(s.js_stamp))
    ev = [(int(t), 0, i) for i, t in enumerate(js_lt.tolist())]
    ev += [(int(t) + 150_000, 1, i) for i, t in enumerate(s.cmd_stamp.tolist())]
    for k, (_fr, tt, _vv) in enumerate(s.temps):
        ev += [(int(t) + 900_000, 2 + k, i) for i, t in enumerate(tt.tolist())]
    if s.extra_topics:
        t0, t1 = int(s.js_stamp.min()), int(s.js_stamp.max())
        ev += [(int(t), -1, i) for i, t in enumerate(range(t0, t1, 20_000_000))]  # /tf at 50 Hz
        ev += [(int(t), -2, i) for i, t in enumerate(range(t0, t1, 250_000_000))]  # /rosout at 4 Hz
    # keep file order = arrival order of each topic (a recorder writes in receive order)
    return ev


def write_mcap_ros2(path: str | Path, s: Streams, *, compression: str = "zstd", chunked: bool = True,
                    chunk_size: int = 64 * 1024) -> Path:
    """Write ``s`` with plain ``mcap-ros2-support`` (no offered_qos_profiles: that tool does not add it)."""
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter
    from mcap_ros2.writer import Writer

    from hd_bag.cdr import SCHEMAS  # only the .msg texts (the same strings `ros2 bag` stores)

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        if chunked:
            w = Writer(f, chunk_size=chunk_size, compression=comp)
        else:  # same tool, unchunked layout (messages directly in the data section)
            w = Writer(io.BytesIO(), chunk_size=chunk_size, compression=comp)
            w._writer = McapWriter(f, chunk_size=chunk_size, compression=comp, use_chunking=False)
            w._writer.start(profile="ros2", library="mcap-ros2-support (unchunked)")
        js = w.register_msgdef("sensor_msgs/msg/JointState", SCHEMAS["sensor_msgs/msg/JointState"])
        tm = w.register_msgdef("sensor_msgs/msg/Temperature", SCHEMAS["sensor_msgs/msg/Temperature"])
        tf = w.register_msgdef("tf2_msgs/msg/TFMessage", _TF_MSGDEF) if s.extra_topics else None
        lg = w.register_msgdef("rcl_interfaces/msg/Log", _LOG_MSGDEF) if s.extra_topics else None
        for lt, kind, i in _events_sorted(s):
            if kind == 0:
                st = int(s.js_stamp[i])
                w.write_message("/hd/joint_states", js, _js_dict(st, s.js[i], s.joint_names), log_time=lt,
                                publish_time=lt)
            elif kind == 1:
                st = int(s.cmd_stamp[i])
                w.write_message("/hd/command", js, {"header": _hdr(st), "name": ["output"],
                                                    "position": [float(s.theta_ref[i])], "velocity": [],
                                                    "effort": []}, log_time=lt, publish_time=lt)
            elif kind >= 2:
                fr, tt, vv = s.temps[kind - 2]
                w.write_message("/hd/temperature", tm, {"header": _hdr(int(tt[i]), fr),
                                                        "temperature": float(vv[i]), "variance": 0.04},
                                log_time=lt, publish_time=lt)
            elif kind == -1:
                w.write_message("/tf", tf, {"transforms": [{"header": _hdr(lt, "base_link"),
                                                            "child_frame_id": "flap",
                                                            "transform": {"translation": {"x": 0.1, "y": 0.0,
                                                                                          "z": 0.0},
                                                                          "rotation": {"x": 0.0, "y": 0.0,
                                                                                       "z": 0.0, "w": 1.0}}}]},
                                log_time=lt, publish_time=lt)
            else:
                w.write_message("/rosout", lg, {"stamp": {"sec": lt // 10**9, "nanosec": lt % 10**9},
                                                "level": 20, "name": "rig_logger", "msg": f"heartbeat {i}",
                                                "file": "logger.cpp", "function": "tick", "line": 42},
                                log_time=lt, publish_time=lt)
        w._writer.add_metadata("hd_mission", dict(s.meta))
        w.finish()
    return path


def _events_sorted(s: Streams):
    """Messages in log-time order, ties kept in arrival order (a recorder's file order)."""
    return sorted(_events(s), key=lambda e: e[0])


def write_rosbags(bag_dir: str | Path, s: Streams, *, compress: bool = True) -> Path:
    """Write ``s`` with ``rosbags`` as a ``ros2 bag``-style directory (``metadata.yaml`` + ``<name>.mcap``).

    rosbags has no API for MCAP metadata records; the ``hd_mission`` record is
    written with rosbags' own record writer into the data section just before
    rosbags closes the file (so the summary has no index entry for it, as with
    several recorders). Returns the ``.mcap`` path.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.rosbag2 import storage_mcap as sm
    from rosbags.typesys import Stores, get_typestore
    from io import BytesIO

    ts = get_typestore(Stores.ROS2_JAZZY)
    JS = ts.types["sensor_msgs/msg/JointState"]
    TM = ts.types["sensor_msgs/msg/Temperature"]
    Hdr = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    LOG = ts.types["rcl_interfaces/msg/Log"]
    bag_dir = Path(bag_dir)
    bag_dir.parent.mkdir(parents=True, exist_ok=True)
    w = Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
    if compress:
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    w.open()
    storage = w.storage
    orig_close = storage.close

    def close_with_meta(version, metadata):
        if storage.chunk.bio.tell():
            storage.close_chunk()
        rec = BytesIO()
        sm.write_string(rec, "hd_mission")
        sub = BytesIO()
        for k, v in s.meta.items():
            sm.write_string(sub, k)
            sm.write_string(sub, v)
        sm.write_uint32(rec, sub.tell())
        rec.write(sub.getbuffer())
        sm.write_record(storage.bio, 0x0C, rec)
        return orig_close(version, metadata)

    storage.close = close_with_meta
    cj = w.add_connection("/hd/joint_states", JS.__msgtype__, typestore=ts)
    cc = w.add_connection("/hd/command", JS.__msgtype__, typestore=ts)
    ct = w.add_connection("/hd/temperature", TM.__msgtype__, typestore=ts) if s.temps else None
    cl = w.add_connection("/rosout", LOG.__msgtype__, typestore=ts) if s.extra_topics else None

    def time(st):
        return Time(sec=int(st // 10**9), nanosec=int(st % 10**9))

    for lt, kind, i in _events_sorted(s):
        if kind == 0:
            st = int(s.js_stamp[i])
            msg = JS(header=Hdr(stamp=time(st), frame_id=""), name=list(s.joint_names),
                     position=np.asarray(s.js[i, 0:2], float), velocity=np.asarray(s.js[i, 2:4], float),
                     effort=np.asarray(s.js[i, 4:6], float))
            w.write(cj, lt, ts.serialize_cdr(msg, JS.__msgtype__))
        elif kind == 1:
            st = int(s.cmd_stamp[i])
            msg = JS(header=Hdr(stamp=time(st), frame_id=""), name=["output"],
                     position=np.array([float(s.theta_ref[i])]), velocity=np.zeros(0), effort=np.zeros(0))
            w.write(cc, lt, ts.serialize_cdr(msg, JS.__msgtype__))
        elif kind >= 2:
            fr, tt, vv = s.temps[kind - 2]
            msg = TM(header=Hdr(stamp=time(int(tt[i])), frame_id=fr), temperature=float(vv[i]), variance=0.04)
            w.write(ct, lt, ts.serialize_cdr(msg, TM.__msgtype__))
        elif kind == -2:
            msg = LOG(stamp=time(lt), level=20, name="rig_logger", msg=f"heartbeat {i}", file="logger.cpp",
                      function="tick", line=42)
            w.write(cl, lt, ts.serialize_cdr(msg, LOG.__msgtype__))
    w.close()
    return next(bag_dir.glob("*.mcap"))


# ---------------------------------------------------------------------------
# variations (each alone), applied to the streams
# ---------------------------------------------------------------------------
def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, 0xF0E1])


def v_jitter(s: Streams, seed: int = 0) -> Streams:
    """Heavy stamp jitter: +-30 % of the sample period (uniform), order preserved."""
    dt = float(np.median(np.diff(s.js_stamp)))
    j = _rng(seed).uniform(-0.3, 0.3, len(s.js_stamp)) * dt
    return replace(s, js_stamp=s.js_stamp + np.rint(j).astype(np.int64))


def v_no_torque_sensor(s: Streams, seed: int = 0) -> Streams:
    js = s.js.copy()
    js[:, 5] = np.nan
    return replace(s, js=js)


def v_no_temperature(s: Streams, seed: int = 0) -> Streams:
    return replace(s, temps=[])


def v_temp_1hz_gearbox(s: Streams, seed: int = 0) -> Streams:
    """Only a gearbox thermocouple at 1 Hz (the contract's minimum rate)."""
    st = s.js_stamp[0] + np.arange(0, int(s.js_stamp[-1] - s.js_stamp[0]) + 1, 10**9, dtype=np.int64)
    fr, tt, vv = next(((f, t, v) for f, t, v in s.temps if f == "gearbox"), s.temps[0])
    v = np.interp(st.astype(float), tt.astype(float), vv)
    return replace(s, temps=[("gearbox", st, v)])


def v_dropout_2s(s: Streams, seed: int = 0) -> Streams:
    """Joint states missing for 2 s in the middle (command and temperature keep coming)."""
    t = (s.js_stamp - s.js_stamp[0]) * 1e-9
    mid = 0.5 * t[-1]
    keep = ~((t > mid - 1.0) & (t < mid + 1.0))
    return replace(s, js_stamp=s.js_stamp[keep], js=s.js[keep])


def v_dup_and_disorder(s: Streams, seed: int = 0) -> Streams:
    """2 % of the samples sent twice, 3 % swapped with their neighbour (arrival order)."""
    rng = _rng(seed)
    n = len(s.js_stamp)
    idx = np.arange(n)
    sw = rng.choice(np.arange(1, n - 2, 3), size=max(1, int(0.03 * n)), replace=False)
    idx[sw], idx[sw + 1] = idx[sw + 1], idx[sw].copy()
    dup = np.sort(rng.choice(n, size=max(1, int(0.02 * n)), replace=False))
    idx = np.insert(idx, np.searchsorted(np.arange(n), dup) + 1, idx[dup])
    return replace(s, js_stamp=s.js_stamp[idx], js=s.js[idx])


def v_theta_m_offset(s: Streams, seed: int = 0) -> Streams:
    """Motor encoder never zeroed: theta_m starts at 1e4 rad (unwrapped; ~1600 turns)."""
    js = s.js.copy()
    js[:, 0] += 1.0e4 + 0.1234
    return replace(s, js=js)


def v_theta_large(s: Streams, seed: int = 0) -> Streams:
    """Both encoders far from zero but co-referenced: theta_m + 1e4 rad, theta_f and theta_ref + 1e4 / N."""
    N = float(s.meta["gear_ratio"])
    js = s.js.copy()
    js[:, 0] += 1.0e4
    js[:, 1] += 1.0e4 / N
    return replace(s, js=js, theta_ref=s.theta_ref + 1.0e4 / N)


def v_theta_m_wrapped(s: Streams, seed: int = 0) -> Streams:
    """A single-turn motor encoder: theta_m logged modulo 2 pi in [-pi, pi) (contract: unwrapped), the shaft 40
    turns from the zero it shares with the output encoder (theta_f co-referenced: + 40 2 pi / N)."""
    N = float(s.meta["gear_ratio"])
    js = s.js.copy()
    js[:, 0] = np.mod(js[:, 0] + 80 * math.pi + math.pi, 2 * math.pi) - math.pi
    js[:, 1] += 80 * math.pi / N
    return replace(s, js=js, theta_ref=s.theta_ref + 80 * math.pi / N)


def v_extra_topics(s: Streams, seed: int = 0) -> Streams:
    return replace(s, extra_topics=True)


def v_names_reversed(s: Streams, seed: int = 0) -> Streams:
    """Joint names in the other order (``["output", "motor"]``): readers map by name, not position."""
    js = s.js[:, [1, 0, 3, 2, 5, 4]]
    return replace(s, js=js, joint_names=("output", "motor"))


def v_meta_spacing(s: Streams, seed: int = 0) -> Streams:
    """Metadata values written by a sloppy tool: padded strings, integer-looking floats, extra keys."""
    meta = dict(s.meta)
    meta["gear_ratio"] = f" {float(meta['gear_ratio']):.1f} "
    meta["operating_hours"] = str(int(float(meta["operating_hours"])))
    meta["rig_serial"] = "B-17"
    return replace(s, meta=meta)


def v_no_command(s: Streams, seed: int = 0) -> Streams:
    """A rig without a position command topic (torque-controlled test bench)."""
    return replace(s, cmd_stamp=s.cmd_stamp[:0], theta_ref=s.theta_ref[:0])


def v_sim_time(s: Streams, seed: int = 0) -> Streams:
    """Stamps from a simulation clock that starts at 0 s (``use_sim_time``), not wall-clock time."""
    t0 = int(s.js_stamp.min())
    return replace(s, js_stamp=s.js_stamp - t0, cmd_stamp=s.cmd_stamp - t0,
                   temps=[(f, tt - t0, vv) for f, tt, vv in s.temps])


def v_speed_rpm(s: Streams, seed: int = 0) -> Streams:
    """A logger that writes both speeds in rpm instead of rad/s."""
    js = s.js.copy()
    js[:, 2:4] *= 60.0 / (2.0 * math.pi)
    return replace(s, js=js)


def v_torque_sign(s: Streams, seed: int = 0) -> Streams:
    """Output torque sensor mounted the other way round (Q_red sign reversed)."""
    js = s.js.copy()
    js[:, 5] *= -1.0
    return replace(s, js=js)


# broken on purpose: must give a clear error, never a traceback
def v_no_joint_states(s: Streams, seed: int = 0) -> Streams:
    return replace(s, js_stamp=s.js_stamp[:0], js=s.js[:0])


def v_meta_missing_kt(s: Streams, seed: int = 0) -> Streams:
    meta = {k: v for k, v in s.meta.items() if k != "torque_constant"}
    return replace(s, meta=meta)


def v_zero_stamps(s: Streams, seed: int = 0) -> Streams:
    """A driver that never fills header.stamp (all zero)."""
    return replace(s, js_stamp=np.zeros_like(s.js_stamp), cmd_stamp=np.zeros_like(s.cmd_stamp))


@dataclass
class Variant:
    """One variation: how to simulate, how to vary, how to write, and what the stack must do."""

    name: str
    doc: str
    sim: dict = field(default_factory=dict)  # kwargs of :func:`simulate`
    vary: Callable[[Streams, int], Streams] | None = None
    writer: str = "mcap_ros2"  # mcap_ros2 | rosbags
    compression: str = "zstd"  # zstd | lz4 | none (rosbags: zstd or none)
    chunked: bool = True
    expect: str = "ok"  # ok | error | flagged (readable, validate reports an error, the twin refuses)
    match: str = ""  # substring the error must contain


VARIANTS: dict[str, Variant] = {v.name: v for v in [
    Variant("plain", "mcap-ros2-support writer, zstd chunks, 1 kHz"),
    Variant("rosbags", "rosbags writer (ros2 bag directory, zstd storage compression)", writer="rosbags"),
    Variant("rosbags_nocomp", "rosbags writer, uncompressed, /rosout present", writer="rosbags", compression="none",
            vary=v_extra_topics),
    Variant("lz4", "lz4 chunk compression", compression="lz4"),
    Variant("uncompressed", "chunks without compression", compression="none"),
    Variant("unchunked", "no chunks at all (messages in the data section)", chunked=False),
    Variant("fs100", "100 Hz joint states", sim={"fs": 100.0, "duration": 4.0}),
    Variant("fs10k", "10 kHz joint states", sim={"fs": 10000.0, "duration": 0.6}),
    Variant("jitter", "stamp jitter +-30 % of the period", vary=v_jitter),
    Variant("no_torque", "Q_red all NaN (no torque sensor)", vary=v_no_torque_sensor),
    Variant("no_temp", "no /hd/temperature topic", vary=v_no_temperature),
    Variant("temp_1hz", "temperature at 1 Hz, gearbox frame only", vary=v_temp_1hz_gearbox,
            sim={"duration": 3.0}),
    Variant("n50", "gear ratio N = 50, k_t = 0.35 N*m/A", sim={"gear_ratio": 50, "k_t": 0.35}),
    Variant("n160", "gear ratio N = 160, k_t = 2.0 N*m/A", sim={"gear_ratio": 160, "k_t": 2.0}),
    Variant("negative", "negative-only motion (ramp down)", sim={"profile": "ramp_neg"}),
    Variant("const_speed", "constant output speed", sim={"profile": "const_speed"}),
    Variant("standstill", "standstill (hold at one angle)", sim={"profile": "hold"}),
    Variant("short", "0.5 s mission", sim={"duration": 0.5}),
    Variant("dropout", "2 s joint-state dropout in a 5 s mission", sim={"duration": 5.0}, vary=v_dropout_2s),
    Variant("dup_disorder", "2 % duplicated, 3 % swapped stamps", vary=v_dup_and_disorder),
    Variant("theta_large", "theta_m near 1e4 rad, theta_f co-referenced (+1e4/N)", vary=v_theta_large),
    Variant("theta_offset", "theta_m offset by 1e4 rad alone (encoders without a common zero)",
            vary=v_theta_m_offset, expect="flagged", match="common zero"),
    Variant("speed_rpm", "omega_m, omega_f in rpm (unit error)", vary=v_speed_rpm, expect="flagged",
            match="in rpm?"),
    Variant("torque_sign", "Q_red sign reversed (sensor mounted the other way)", vary=v_torque_sign,
            expect="flagged", match="sign reversed?"),
    Variant("theta_wrapped", "theta_m logged within one turn (single-turn encoder, modulo 2 pi)",
            vary=v_theta_m_wrapped),
    Variant("extra_topics", "/tf and /rosout in the bag", vary=v_extra_topics),
    Variant("no_command", "no /hd/command topic", vary=v_no_command),
    Variant("sim_time", "stamps from a clock starting at 0 s", vary=v_sim_time),
    Variant("names_reversed", "joint names [output, motor]", vary=v_names_reversed),
    Variant("meta_sloppy", "padded metadata strings, extra keys", vary=v_meta_spacing),
    Variant("no_joint_states", "no /hd/joint_states", vary=v_no_joint_states, expect="error",
            match="/hd/joint_states"),
    Variant("no_kt", "hd_mission without torque_constant", vary=v_meta_missing_kt, expect="error",
            match="torque_constant"),
    Variant("zero_stamps", "header.stamp never filled", vary=v_zero_stamps, expect="error", match="stamp"),
]}


def _custom_profile(kind: str, duration: float, fs: float, seed: int):
    """Profiles the simulator has no preset for (negative-only ramp, constant speed)."""
    from hd_sim.profiles import make_profile

    p = make_profile("ramp", duration, fs, seed)
    n = p.n
    t = np.arange(n) / fs
    if kind == "ramp_neg":  # from 0 down at -20 deg/s after a 0.2 s hold
        w = -math.radians(20.0) * (t > 0.2)
    else:  # const_speed: +15 deg/s from the first sample
        w = np.full(n, math.radians(15.0))
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / fs)])
    p.theta_ref = theta
    p.omega_ff = w
    return p


def make_streams(v: Variant, *, seed: int = 0, actuator_id: str = "FX-0001", mission_index: int = 0,
                 operating_hours: float = 0.0, health: dict | None = None) -> Streams:
    kw = dict(v.sim)
    prof = kw.pop("profile", "inspection")
    if prof in ("ramp_neg", "const_speed"):
        fs = kw.get("fs", 1000.0)
        prof = _custom_profile(prof, kw.get("duration", 2.0), fs, seed)
    m = simulate(seed=seed, profile=prof, health=health, **kw)
    s = streams_from_mission(m, actuator_id=actuator_id, mission_index=mission_index,
                             operating_hours=operating_hours)
    return v.vary(s, seed) if v.vary else s


def write_variant(out_dir: str | Path, v: Variant, **kw) -> Path:
    """Generate and write one variant under ``out_dir``; returns the ``.mcap`` path."""
    s = make_streams(v, **kw)
    out_dir = Path(out_dir)
    if v.writer == "rosbags":
        return write_rosbags(out_dir / v.name, s, compress=v.compression != "none")
    return write_mcap_ros2(out_dir / f"{v.name}.mcap", s, compression=v.compression, chunked=v.chunked)


def write_all(out_dir: str | Path, names=None) -> dict[str, Path]:
    return {n: write_variant(out_dir, VARIANTS[n]) for n in (names or VARIANTS)}


def write_actuator(out_dir: str | Path, *, actuator_id: str = "FX-0100", indices=(0, 1, 3, 4, 7, 8),
                   writer: str = "rosbags", seed: int = 100, wear_um_per_index: float = 2.0,
                   duration: float = 2.0) -> list[Path]:
    """One actuator's life as another tool files it: ``mission_index`` with gaps, files named so that
    name order != mission order (a date-less recorder name with a random suffix), rosbags directories or
    flat .mcap files, wear growing with the index (the simulator's health input)."""
    out_dir = Path(out_dir)
    rng = np.random.default_rng(seed)
    paths = []
    names = rng.permutation(len(indices))
    for k, mi in enumerate(indices):
        h = wear_um_per_index * 1e-6 * mi
        s = make_streams(Variant("life", "", sim={"duration": duration}), seed=seed + mi, actuator_id=actuator_id,
                         mission_index=mi, operating_hours=140.0 * mi, health={"h_plus": h, "h_minus": h})
        stem = f"rec_{names[k]:02d}_{rng.integers(1 << 30):08x}"
        if writer == "rosbags":
            paths.append(write_rosbags(out_dir / stem, s))
        else:
            paths.append(write_mcap_ros2(out_dir / f"{stem}.mcap", s))
    return paths


if __name__ == "__main__":  # pragma: no cover - manual use: python -m tests.robustness.foreign OUT
    import sys

    out = Path(sys.argv[1] if len(sys.argv) > 1 else "bags/foreign")
    for n, p in write_all(out).items():
        print(f"{n:16s} {p}")
    write_actuator(out / "actuator_rosbags")
