"""Builders of small hostile bags (issue 13): each is generated in the test, a few KB to a few MB."""

from __future__ import annotations

import struct

import numpy as np

from hd_bag import cdr, write_mission
from hd_bag.mcapio import (MAGIC, MSG_FIXED, OP_DATA_END, OP_FOOTER, OP_MESSAGE, McapFileWriter, _record,
                           channel_record, header_record, metadata_record, schema_record)

JS = "sensor_msgs/msg/JointState"


def records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every record of an intact MCAP byte string, summary included."""
    out, p = [], 8
    while p + 9 <= len(data) - 8:
        op, ln = struct.unpack_from("<BQ", data, p)
        out.append((p, op, ln))
        if op == OP_FOOTER:
            break
        p += 9 + ln
    return out


def meta_dict(m) -> dict[str, str]:
    mm = m.meta
    return {"contract": "1", "actuator_id": str(mm.actuator_id), "mission_index": str(mm.mission_index),
            "operating_hours": repr(float(mm.operating_hours)), "gear_ratio": repr(float(mm.gear_ratio)),
            "torque_constant": repr(float(mm.torque_constant)), "source": mm.source}


def js_payloads(m) -> np.ndarray:
    lay = cdr.jointstate_layout(["motor", "output"])
    st = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    return st, cdr.encode_jointstate(lay, st, np.stack([m.theta_m, m.theta_f], 1), np.stack([m.omega_m, m.omega_f], 1),
                                     np.stack([m.tau_m, m.Q_red], 1))


def unchunked_bag(path, m, meta: dict[str, str] | None = None) -> tuple[str, list[int]]:
    """A contract bag with every message outside chunks (no CRC anywhere); returns (path, offset of each
    joint-state payload)."""
    st, rows = js_payloads(m)
    out = bytearray(MAGIC + header_record("ros2", "hostile"))
    out += schema_record(1, JS, "ros2msg", cdr.SCHEMAS[JS].encode())
    out += channel_record(0, 1, "/hd/joint_states", "cdr", {"offered_qos_profiles": ""})
    out += metadata_record("hd_mission", meta or meta_dict(m))
    offs = []
    for i, (s, r) in enumerate(zip(st.tolist(), rows)):
        offs.append(len(out) + 9 + MSG_FIXED)
        out += _record(OP_MESSAGE, struct.pack("<HIQQ", 0, i, s, s) + r.tobytes())
    out += _record(OP_DATA_END, struct.pack("<I", 0))
    out += _record(OP_FOOTER, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    with open(path, "wb") as f:
        f.write(out)
    return str(path), offs


def one_message_bag(path, payload: bytes, meta: dict[str, str], schema_name: str = JS, topic="/hd/joint_states",
                    compression: str = "zstd") -> str:
    """A chunked bag whose only message on ``topic`` is ``payload`` (plus its hd_mission record)."""
    w = McapFileWriter(path, compression=compression)
    w.add_schema(1, schema_name, "ros2msg", cdr.SCHEMAS[JS].encode())
    w.add_channel(0, 1, topic, "cdr", {"offered_qos_profiles": ""})
    w.add_metadata("hd_mission", meta)
    rec = _record(OP_MESSAGE, struct.pack("<HIQQ", 0, 0, 1, 1) + payload)
    w.write_chunk([(0, np.array([1], np.uint64), [rec])])
    w.close()
    return str(path)


def huge_jointstate(n: int) -> bytes:
    """A JointState whose position array holds ``n`` zeros (compresses to almost nothing)."""
    body = bytearray(8) + struct.pack("<I", 1) + b"\x00" + bytes(3)  # stamp, frame_id "", pad to 16
    body += struct.pack("<II", 0, n)  # no names, n positions (offset 24: aligned to 8)
    return cdr.ENCAP_LE + bytes(body) + bytes(8 * n) + struct.pack("<II", 0, 0)


def good_bag(path, m, **kw) -> str:
    return write_mission(path, m, **kw)
