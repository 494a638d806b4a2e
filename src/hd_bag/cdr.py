"""Vectorised CDR (XCDR1, little endian) for the contract's fixed message types.

ROS 2 serialises ``sensor_msgs/msg/JointState`` and ``sensor_msgs/msg/Temperature``
as plain CDR: a 4-byte encapsulation header (``00 01 00 00`` = CDR little
endian) then the fields, each aligned to its own size relative to the end of
that header. When every message of a topic has the same frame_id and the same
joint names (the normal case), all messages have the same byte layout and only
the stamp and the float64 values differ, so a whole block of messages is one
(n, L) uint8 array whose float64 columns are read with a single ``view``.

Anything else (other name lengths per message, big-endian CDR, another type) is
decoded with ``mcap-ros2-support``'s generic decoder: slower, always correct.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

#: Schema texts as ``ros2 bag``/``rosbags`` write them: the message then each
#: dependency after a line of 80 '=' and ``MSG: pkg/Type``.
_SEP = "=" * 80 + "\n"
_HEADER_DEPS = (_SEP + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
                + _SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
SCHEMAS = {
    "sensor_msgs/msg/JointState": "std_msgs/Header header\nstring[] name\nfloat64[] position\n"
                                  "float64[] velocity\nfloat64[] effort\n" + _HEADER_DEPS,
    "sensor_msgs/msg/Temperature": "std_msgs/Header header\nfloat64 temperature\nfloat64 variance\n" + _HEADER_DEPS,
    "std_msgs/msg/String": "string data\n",
}

ENCAP_LE = b"\x00\x01\x00\x00"
#: Most joints (names and array entries) a JointState may carry: the contract has 2 (motor, output),
#: 1 on /hd/command; rigs that log extra joints on the topic stay far below 64.
MAX_JOINTS = 64


def normalise_type(name: str) -> str:
    """``sensor_msgs/JointState`` -> ``sensor_msgs/msg/JointState``."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def _align(p: int, a: int) -> int:
    return (p + a - 1) // a * a


def _str(body: bytearray, s: str) -> None:
    b = s.encode("utf-8") + b"\x00"
    while len(body) % 4:
        body.append(0)
    body += struct.pack("<I", len(b)) + b


@dataclass(frozen=True)
class JointStateLayout:
    """Byte layout of a JointState payload (offsets from the payload start)."""

    frame_id: str
    names: tuple[str, ...]
    counts: tuple[int, int, int]  # position, velocity, effort lengths
    offsets: tuple[int, int, int]  # byte offset of the first double of each array
    size: int  # payload length
    mask: np.ndarray  # bool[size]: bytes that must equal the template (not stamp, data or padding)
    template: np.ndarray  # uint8[size]


def jointstate_layout(names, frame_id: str = "", counts=None) -> JointStateLayout:
    """Layout for a JointState with these names and array lengths (default: all ``len(names)``)."""
    names = tuple(names)
    counts = tuple(counts) if counts is not None else (len(names),) * 3
    body = bytearray(8)  # stamp
    keep = [False] * 8
    _str(body, frame_id)
    keep += [True] * (len(body) - len(keep))
    # pad + name count
    while len(body) % 4:
        body.append(0)
        keep.append(False)
    body += struct.pack("<I", len(names))
    keep += [True] * 4
    for nm in names:
        while len(body) % 4:
            body.append(0)
            keep.append(False)
        b = nm.encode("utf-8") + b"\x00"
        body += struct.pack("<I", len(b)) + b
        keep += [True] * (4 + len(b))
    offs = []
    for k in counts:
        while len(body) % 4:
            body.append(0)
            keep.append(False)
        body += struct.pack("<I", k)
        keep += [True] * 4
        if k:
            while len(body) % 8:
                body.append(0)
                keep.append(False)
        offs.append(len(body) + 4)
        body += bytes(8 * k)
        keep += [False] * (8 * k)
    raw = ENCAP_LE + bytes(body)
    mask = np.array([True, True, False, False] + keep, bool)  # options bytes may carry padding info
    return JointStateLayout(frame_id, names, counts, tuple(offs), len(raw), mask,
                            np.frombuffer(raw, np.uint8).copy())


def parse_jointstate_layout(payload: bytes) -> JointStateLayout | None:
    """Layout of one serialised JointState, or None when it is not little-endian CDR."""
    if len(payload) < 4 + 12 or payload[1] != 1 or payload[0] != 0:
        return None
    b = payload
    try:
        p = 4 + 8
        ln = struct.unpack_from("<I", b, p)[0]
        frame = b[p + 4:p + 4 + ln - 1].decode("utf-8") if ln else ""
        p = p + 4 + ln
        p = 4 + _align(p - 4, 4)
        n = struct.unpack_from("<I", b, p)[0]
        p += 4
        if n > MAX_JOINTS:
            return None
        names = []
        for _ in range(n):
            p = 4 + _align(p - 4, 4)
            ln = struct.unpack_from("<I", b, p)[0]
            names.append(b[p + 4:p + 4 + ln - 1].decode("utf-8") if ln else "")
            p += 4 + ln
        counts = []
        for _ in range(3):
            p = 4 + _align(p - 4, 4)
            k = struct.unpack_from("<I", b, p)[0]
            if k > MAX_JOINTS:
                return None
            counts.append(k)
            p += 4
            if k:
                p = 4 + _align(p - 4, 8)
            p += 8 * k
        if p > len(b):
            return None
    except (struct.error, UnicodeDecodeError):
        return None
    lay = jointstate_layout(names, frame, counts)
    if lay.size != len(payload):
        # trailing alignment padding some serialisers add: accept, layout still fixed
        if len(payload) < lay.size or len(payload) - lay.size > 64:
            return None
        extra = len(payload) - lay.size
        mask = np.concatenate([lay.mask, np.zeros(extra, bool)])
        tmpl = np.concatenate([lay.template, np.zeros(extra, np.uint8)])
        lay = JointStateLayout(lay.frame_id, lay.names, lay.counts, lay.offsets, len(payload), mask, tmpl)
    return lay


def stamps_to_sec_nsec(stamp_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stamp_ns = np.asarray(stamp_ns, np.int64)
    sec = np.floor_divide(stamp_ns, 1_000_000_000)
    return sec.astype("<i4"), (stamp_ns - sec * 1_000_000_000).astype("<u4")


def encode_jointstate(layout: JointStateLayout, stamp_ns: np.ndarray, position=None, velocity=None,
                      effort=None) -> np.ndarray:
    """Serialise n JointState messages: (n, layout.size) uint8. Value arrays are (n, count)."""
    n = len(stamp_ns)
    out = np.tile(layout.template, (n, 1))
    sec, nsec = stamps_to_sec_nsec(stamp_ns)
    out[:, 4:8] = sec.view(np.uint8).reshape(n, 4)
    out[:, 8:12] = nsec.view(np.uint8).reshape(n, 4)
    for vals, off, k in zip((position, velocity, effort), layout.offsets, layout.counts):
        if k == 0:
            continue
        v = np.ascontiguousarray(np.broadcast_to(np.asarray(vals, "<f8").reshape(n, -1), (n, k)), "<f8")
        out[:, off:off + 8 * k] = v.view(np.uint8).reshape(n, 8 * k)
    return out


def decode_stamps(rows: np.ndarray) -> np.ndarray:
    """header.stamp of n serialised messages (rows (n, L) uint8), as int64 ns."""
    sec = np.ascontiguousarray(rows[:, 4:8]).view("<i4").ravel().astype(np.int64)
    nsec = np.ascontiguousarray(rows[:, 8:12]).view("<u4").ravel().astype(np.int64)
    return sec * 1_000_000_000 + nsec


def decode_doubles(rows: np.ndarray, off: int, k: int) -> np.ndarray:
    """(n, k) float64 starting at byte ``off`` of each row."""
    return np.ascontiguousarray(rows[:, off:off + 8 * k]).view("<f8").reshape(len(rows), k)


def match_layout(rows: np.ndarray, layout: JointStateLayout) -> np.ndarray:
    """bool[n]: rows whose fixed bytes equal the layout's template."""
    m = layout.mask
    return np.all(rows[:, m] == layout.template[m], axis=1)


# ---- Temperature -----------------------------------------------------------
def temperature_layout(frame_id: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(template, mask, offset of ``temperature``) for a Temperature payload."""
    body = bytearray(8)
    _str(body, frame_id)
    n_fixed = len(body)
    while len(body) % 8:
        body.append(0)
    off = 4 + len(body)
    body += bytes(16)
    raw = ENCAP_LE + bytes(body)
    mask = np.zeros(len(raw), bool)
    mask[:2] = True
    mask[12:4 + n_fixed] = True
    return np.frombuffer(raw, np.uint8).copy(), mask, off


def parse_temperature_frame(payload: bytes) -> str | None:
    if len(payload) < 16 or payload[0] != 0 or payload[1] != 1:
        return None
    ln = struct.unpack_from("<I", payload, 12)[0]
    if 16 + ln > len(payload):
        return None
    try:
        return payload[16:16 + ln - 1].decode("utf-8") if ln else ""
    except UnicodeDecodeError:
        return None


def encode_temperature(frame_id: str, stamp_ns: np.ndarray, temperature: np.ndarray,
                       variance: float | np.ndarray = 0.0) -> np.ndarray:
    tmpl, _, off = temperature_layout(frame_id)
    n = len(stamp_ns)
    out = np.tile(tmpl, (n, 1))
    sec, nsec = stamps_to_sec_nsec(stamp_ns)
    out[:, 4:8] = sec.view(np.uint8).reshape(n, 4)
    out[:, 8:12] = nsec.view(np.uint8).reshape(n, 4)
    v = np.stack([np.asarray(temperature, "<f8"), np.broadcast_to(np.asarray(variance, "<f8"), (n,))], 1)
    out[:, off:off + 16] = np.ascontiguousarray(v).view(np.uint8).reshape(n, 16)
    return out


def encode_string(text: str) -> bytes:
    b = text.encode("utf-8") + b"\x00"
    return ENCAP_LE + struct.pack("<I", len(b)) + b


# ---- generic fallback --------------------------------------------------------
_DECODERS: dict[tuple[str, str], object] = {}


def generic_decoder(type_name: str, schema_text: bytes | None = None):
    """mcap-ros2-support decoder function for one of the contract's types (cached).

    The decoder is built from this module's fixed :data:`SCHEMAS` text, never from a schema found in
    a file (``schema_text`` is accepted for compatibility and ignored): a bag names a type, it does
    not get to define how we parse it. A type outside the table raises ValueError."""
    name = normalise_type(type_name)
    dec = _DECODERS.get(name)
    if dec is None:
        if name not in SCHEMAS:
            raise ValueError(f"message type {type_name!r} is not one the contract reader decodes "
                             f"({', '.join(sorted(SCHEMAS))})")
        from mcap_ros2._dynamic import generate_dynamic

        dec = generate_dynamic(name, SCHEMAS[name])[name]
        _DECODERS[name] = dec
    return dec
