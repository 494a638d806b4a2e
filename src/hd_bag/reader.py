"""Contract bag reader: :func:`read_mission`, :func:`validate_bag`, :func:`iter_messages`.

One streaming pass over the MCAP (:func:`hd_bag.mcapio.scan_mcap`, one chunk in
memory at a time) decodes the contract topics into numpy arrays: same-layout
JointState/Temperature messages by the vectorised CDR path, anything else
through the generic ``mcap-ros2-support`` decoder. The assembled data are then
checked against ``../shared/CONTRACT.md``:

What is *fatal* (``read_mission`` raises :class:`BagError`; ``validate_bag``
reports an error):
  not an MCAP file; corrupt bytes (CRC mismatch, undecodable chunk, impossible
  record); a size beyond its cap (``mcapio.MAX_CHUNK_BYTES`` declared or decompressed,
  record lengths); no ``/hd/joint_states`` (or fewer than 2 usable samples); a contract
  topic with the wrong message type or encoding; JointState without the
  ``motor``/``output`` joints; missing ``hd_mission`` metadata, a missing
  required key, an unparsable or absurd value (gear ratio <= 0, k_t <= 0,
  non-finite numbers, operating hours above 1e6 h, an ``actuator_id`` that is not a
  safe file name, unknown source or contract version); grossly
  non-monotonic stamps (a backward jump of more than 50 sample periods, more
  than 10 % of samples out of order, or most stamps repeated: the stamp clock
  is broken, re-sorting would invent a history); more than 1 % of a signal
  beyond physical limits.

What the reader *repairs and reports* (``Mission.report``; validate: warning
unless noted): a truncated file (complete chunks recovered; validate: error),
a damaged record header in the data section (linear resync on the next valid
record; an index record lost: warning, a chunk lost: error), a damaged
summary or footer (the data section is complete: warning), messages above
:data:`MAX_MESSAGE_BYTES` (not decoded; validate: error), bags or chunks
without a CRC (warning; isolated bit-flip spikes read as NaN, validate: error),
slightly out-of-order samples (re-sorted), duplicate stamps (first kept),
dropouts (``report.gaps``, ``Mission.segment`` split at gaps > 10 samples,
never interpolated), NaN (kept), isolated values beyond physical limits (set to
NaN; validate: error per sample), a sample rate outside 100 Hz to 20 kHz
(validate: error), missing ``/hd/command`` or ``/hd/temperature`` (empty arrays),
temperature frames other than ``motor_winding``/``gearbox`` (skipped; validate:
error), missing ``offered_qos_profiles`` (validate: warning). Stamp jitter is
measured (robust sigma of the steps) and a step counts as a dropout only beyond
1.5 periods and 3 jitter sigmas.

What the reader *flags* (readable, ``report.suspect``; validate: error): signals
that contradict each other or the contract, as other tools' unit and sign
mistakes do: ``theta_f - theta_m / N`` beyond ``MAX_TWIST_OFFSET`` (encoders
without a common zero), speeds that are not the derivative of the angles
(``SPEED_SCALE_BAND``: rpm, deg/s, reversed sign), ``Q_red`` anti-correlated
with the wind-up (torque sensor sign; validate: warning, the contract page does
not state that sign), a ``gear_ratio`` the encoders contradict (slope of
theta_m on theta_f beyond :data:`GEAR_RATIO_TOLERANCE`: the metadata has no CRC).

Nothing a file names is imported or executed: contract types are decoded with
this package's fixed schemas (``cdr.SCHEMAS``), :func:`iter_messages` maps type
names through a fixed table and yields other types as :class:`RawMessage`.
"""

from __future__ import annotations

import heapq
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator

import numpy as np

from . import cdr
from .errors import BagError, Violation
from .mcapio import McapFormatError, McapScan, MessageBlock, gather_rows, payloads, scan_mcap
from .mission import (CONTRACT_TOPICS, JOINT_SIGNALS, MAX_INTERP_GAP_SAMPLES, MAX_TWIST_OFFSET, REQUIRED_META_KEYS, SOURCES,
                      TEMPERATURE_FRAMES, TOPIC_COMMAND, TOPIC_JOINT_STATES, TOPIC_TEMPERATURE, Mission,
                      MissionMeta, ReadReport)
from .writer import SIM_TOPICS, TOPIC_SIM_EFFECTS, TOPIC_SIM_HEALTH, TOPIC_SIM_INTERNAL, check_meta

EXPECTED_TYPES = {
    TOPIC_JOINT_STATES: "sensor_msgs/msg/JointState",
    TOPIC_COMMAND: "sensor_msgs/msg/JointState",
    TOPIC_TEMPERATURE: "sensor_msgs/msg/Temperature",
    TOPIC_SIM_INTERNAL: "sensor_msgs/msg/JointState",
    TOPIC_SIM_HEALTH: "sensor_msgs/msg/JointState",
    TOPIC_SIM_EFFECTS: "std_msgs/msg/String",
}

#: |value| above which a sample is not physical for an actuator of this class (SI units).
PHYSICAL_LIMITS = {
    "theta_m": 1e7,  # rad (unwrapped motor angle: ~1.6 million turns)
    "theta_f": 1e5,  # rad
    "omega_m": 1e4,  # rad/s (~95,000 rpm)
    "omega_f": 1e3,  # rad/s
    "tau_m": 1e3,  # N*m at the motor
    "Q_red": 1e6,  # N*m at the output
    "theta_ref": 1e5,  # rad
}
TEMPERATURE_RANGE = (-100.0, 400.0)  # degC
RATE_RANGE = (100.0, 20_000.0)  # Hz, contract
MAX_BACKWARD_PERIODS = 50
MAX_REORDERED_FRACTION = 0.10
MAX_ABSURD_FRACTION = 0.01
_MAX_LAYOUTS = 8
#: Largest serialised message accepted per contract type, checked *before* decoding (a 9 KB zstd
#: chunk can hold one JointState of 10^7 doubles). A contract JointState has 2 joints (~130 bytes);
#: the cap allows cdr.MAX_JOINTS joints with 256-byte names and three arrays of doubles (~25 KiB);
#: a Temperature has one frame id; /sim/effects is a JSON list of a few effects.
MAX_MESSAGE_BYTES = {
    "sensor_msgs/msg/JointState": 64 << 10,
    "sensor_msgs/msg/Temperature": 4 << 10,
    "std_msgs/msg/String": 1 << 20,
}
#: Relative mismatch between the gear ratio seen by the encoders (slope of theta_m against theta_f
#: over moving stretches) and the metadata's ``gear_ratio`` beyond which validate reports an error.
#: Compliance and kinematic error move the slope by well under 1 % (theta_m = N theta_f + twist,
#: twist ~ 1e-3 rad against output strokes of 0.1-1 rad); a wrong N (101 vs 181, 100 vs 1) is off by
#: tens of percent or more.
GEAR_RATIO_TOLERANCE = 0.05
#: rad of output motion per ~10 ms increment below which an increment does not count as moving for the
#: gear-ratio check (0.1 rad/s at the output: twist changes over 10 ms are far smaller).
MIN_OUTPUT_INCREMENT = 1e-3
#: An isolated sample is a bit flip (bags without a CRC only) when it leaves the line through its two
#: neighbours by more than this many robust sigmas of the signal's sample-to-sample steps while the
#: neighbours agree with each other.
SPIKE_SIGMAS = 50.0


# ---------------------------------------------------------------------------
# raw pass
# ---------------------------------------------------------------------------
@dataclass
class _Problem:
    topic: str | None
    index: np.ndarray | None  # message indices on the topic (file order) or None
    problem: str
    severity: str = "error"  # error | warning
    fatal: bool = False


@dataclass
class _JSAcc:
    """Accumulated JointState groups of one topic."""

    stamps: list[np.ndarray] = field(default_factory=list)
    index: list[np.ndarray] = field(default_factory=list)
    names: list[tuple[str, ...]] = field(default_factory=list)
    pos: list[np.ndarray] = field(default_factory=list)
    vel: list[np.ndarray] = field(default_factory=list)
    eff: list[np.ndarray] = field(default_factory=list)


@dataclass
class _TempAcc:
    stamps: list[np.ndarray] = field(default_factory=list)
    index: list[np.ndarray] = field(default_factory=list)
    value: list[np.ndarray] = field(default_factory=list)
    frame: list[str] = field(default_factory=list)


@dataclass
class _Raw:
    path: str
    scan: McapScan
    counts: dict[str, int] = field(default_factory=dict)
    js: dict[str, _JSAcc] = field(default_factory=dict)
    temp: _TempAcc = field(default_factory=_TempAcc)
    strings: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    problems: list[_Problem] = field(default_factory=list)
    bad_channels: set[int] = field(default_factory=set)
    checked_channels: set[int] = field(default_factory=set)


def _layout_groups(block: MessageBlock, sel: np.ndarray, first_index: int, match_layout, schema):
    """Split messages ``sel`` of a block into same-layout groups for the vectorised decoder.

    Messages are grouped by length; within a length, ``match_layout(rows, i0)``
    parses the layout of row ``i0`` and returns ``(layout, mask)`` of the rows
    that share it (or ``None`` when the row is not of a fixed layout). Yields
    ``("fast", rows, message_index, layout)`` per group, at most
    ``_MAX_LAYOUTS`` per length, then ``("generic", msg, message_index, None)``
    for every message left, decoded by the generic ROS 2 decoder.
    """
    idx_all = first_index + np.arange(len(sel))
    lens = block.length[sel]
    for L in np.unique(lens):
        m_L = lens == L
        sub = sel[m_L]
        sub_idx = idx_all[m_L]
        rows = gather_rows(block, sub, int(L))
        left = np.ones(len(sub), bool)
        for _ in range(_MAX_LAYOUTS):
            if not left.any():
                break
            i0 = int(np.argmax(left))
            found = match_layout(rows, i0, left, int(L))
            if found is None:
                break
            lay, m = found
            if not m[i0]:
                break
            yield "fast", rows[m], sub_idx[m], lay
            left &= ~m
        if left.any():
            dec = cdr.generic_decoder(schema)
            for data, ii in zip(payloads(block, sub[left]), sub_idx[left].tolist()):
                yield "generic", dec(data), np.array([ii]), None


def _stamp_ns(msg) -> np.ndarray:
    st = msg.header.stamp
    return np.array([int(st.sec) * 1_000_000_000 + int(st.nanosec)], np.int64)


def _match_js(rows: np.ndarray, i0: int, left: np.ndarray, L: int):
    lay = cdr.parse_jointstate_layout(rows[i0].tobytes())
    if lay is None:
        return None
    m = left.copy()
    m[left] = cdr.match_layout(rows[left], lay)
    return lay, m


def _match_temp(rows: np.ndarray, i0: int, left: np.ndarray, L: int):
    frame = cdr.parse_temperature_frame(rows[i0].tobytes())
    if frame is None:
        return None
    tmpl, mask, off = cdr.temperature_layout(frame)
    if off + 16 > L:
        return None
    m = left.copy()
    m[left] = np.all(rows[left][:, :len(tmpl)][:, mask] == tmpl[mask], axis=1)
    return (frame, off), m


def _decode_js(block: MessageBlock, sel: np.ndarray, first_index: int, acc: _JSAcc, schema) -> int:
    """Decode the JointState messages ``sel`` of a block into ``acc``; returns the generic-path count."""
    n_generic = 0
    for kind, r, idx, lay in _layout_groups(block, sel, first_index, _match_js, schema):
        acc.index.append(idx)
        if kind == "fast":
            acc.stamps.append(cdr.decode_stamps(r))
            acc.names.append(lay.names)
            acc.pos.append(cdr.decode_doubles(r, lay.offsets[0], lay.counts[0]))
            acc.vel.append(cdr.decode_doubles(r, lay.offsets[1], lay.counts[1]))
            acc.eff.append(cdr.decode_doubles(r, lay.offsets[2], lay.counts[2]))
        else:
            acc.stamps.append(_stamp_ns(r))
            acc.names.append(tuple(r.name))
            acc.pos.append(np.asarray(r.position, np.float64)[None, :])
            acc.vel.append(np.asarray(r.velocity, np.float64)[None, :])
            acc.eff.append(np.asarray(r.effort, np.float64)[None, :])
            n_generic += 1
    return n_generic


def _decode_temp(block: MessageBlock, sel: np.ndarray, first_index: int, acc: _TempAcc, schema) -> None:
    for kind, r, idx, lay in _layout_groups(block, sel, first_index, _match_temp, schema):
        acc.index.append(idx)
        if kind == "fast":
            frame, off = lay
            acc.stamps.append(cdr.decode_stamps(r))
            acc.value.append(cdr.decode_doubles(r, off, 1)[:, 0].copy())
            acc.frame.append(frame)
        else:
            acc.stamps.append(_stamp_ns(r))
            acc.value.append(np.array([float(r.temperature)]))
            acc.frame.append(str(r.header.frame_id))


def _decode_topic(raw: _Raw, block: MessageBlock, sel: np.ndarray, first: int, topic: str, schema) -> None:
    """Decode messages ``sel`` of a checked contract (or /sim) channel as the type the contract fixes
    for ``topic`` (never as a type the file names: the schema was checked against it)."""
    typ = EXPECTED_TYPES[topic]
    if typ == "sensor_msgs/msg/JointState":
        _decode_js(block, sel, first, raw.js.setdefault(topic, _JSAcc()), typ)
    elif typ == "sensor_msgs/msg/Temperature":
        _decode_temp(block, sel, first, raw.temp, typ)
    else:  # std_msgs/String (/sim/effects)
        dec = cdr.generic_decoder(typ)
        for data, lt in zip(payloads(block, sel), block.log_time[sel].tolist()):
            raw.strings.setdefault(topic, []).append((int(lt), dec(data).data))


def _scan(path: str, include_sim: bool) -> _Raw:
    if not os.path.exists(path):
        raise BagError(path, "no such file")
    if os.path.isdir(path):
        raise BagError(path, "is a directory, not an MCAP file (pass the .mcap inside it)")
    raw = _Raw(path, McapScan())
    wanted = set(CONTRACT_TOPICS) | (set(SIM_TOPICS) if include_sim else set())
    idx_next: dict[str, int] = {}
    try:
        for block in scan_mcap(path, raw.scan):
            if len(block.channel) == 0:
                continue
            for cid in np.unique(block.channel).tolist():
                ch = raw.scan.channels.get(cid)
                sel = np.nonzero(block.channel == cid)[0]
                if ch is None:
                    raw.problems.append(_Problem(None, None, f"{len(sel)} messages on channel id {cid} that no "
                                                 "Channel record declares (skipped)"))
                    continue
                topic = ch.topic
                raw.counts[topic] = raw.counts.get(topic, 0) + len(sel)
                first = idx_next.get(topic, 0)
                idx_next[topic] = first + len(sel)
                if topic not in wanted or cid in raw.bad_channels:
                    continue
                schema = raw.scan.schemas.get(ch.schema_id)
                if cid not in raw.checked_channels:
                    raw.checked_channels.add(cid)
                    expected = EXPECTED_TYPES[topic]
                    got = cdr.normalise_type(schema.name) if schema else None
                    prob = None
                    if schema is None:
                        prob = f"channel {cid} refers to schema {ch.schema_id}, which is not in the file"
                    elif got != expected:
                        prob = f"wrong message type {schema.name!r} (contract: {expected})"
                    elif ch.message_encoding != "cdr":
                        prob = f"message encoding {ch.message_encoding!r} (contract: cdr)"
                    elif schema.encoding != "ros2msg":
                        prob = f"schema encoding {schema.encoding!r} (contract: ros2msg)"
                    if prob:
                        raw.bad_channels.add(cid)
                        raw.problems.append(_Problem(topic, None, prob, fatal=topic in CONTRACT_TOPICS))
                        continue
                    if "offered_qos_profiles" not in ch.metadata:
                        raw.problems.append(_Problem(topic, None, "channel has no offered_qos_profiles metadata "
                                                     "(the contract's writers add it; readers do not need it)",
                                                     "warning"))
                typ = EXPECTED_TYPES[topic]
                cap = MAX_MESSAGE_BYTES[typ]
                big = block.length[sel] > cap
                if not big.any():
                    _decode_topic(raw, block, sel, first, topic, schema)
                    continue
                raw.problems.append(_Problem(topic, first + np.flatnonzero(big),
                                             f"message of {int(block.length[sel][big].max())} bytes is above the "
                                             f"cap of {cap} bytes for a {typ} (MAX_MESSAGE_BYTES; contract: "
                                             f"2 joints, cap {cdr.MAX_JOINTS}); not decoded"))
                # decode the others run by run, so each keeps its message index on the topic
                keep = np.concatenate([[False], ~big, [False]]).astype(np.int8)
                edges = np.flatnonzero(np.diff(keep))
                for a_, b_ in zip(edges[0::2].tolist(), edges[1::2].tolist()):
                    _decode_topic(raw, block, sel[a_:b_], first + a_, topic, schema)
    except McapFormatError as e:
        raise BagError(path, str(e)) from None
    except Exception as e:  # generic decoder on garbage bytes and similar
        if isinstance(e, BagError):
            raise
        raise BagError(path, f"undecodable message data ({type(e).__name__}: {e})") from None
    for iss in raw.scan.issues:
        raw.problems.append(_Problem(None, None, iss.problem, iss.severity, iss.fatal))
    if raw.scan.profile and raw.scan.profile != "ros2":
        raw.problems.append(_Problem(None, None, f"MCAP profile {raw.scan.profile!r} (contract: ros2)"))
    return raw


# ---------------------------------------------------------------------------
# assembly
# ---------------------------------------------------------------------------
def _parse_meta(raw: _Raw) -> MissionMeta | None:
    rec = raw.scan.metadata.get("hd_mission")
    if rec is None:
        names = sorted(raw.scan.metadata)
        raw.problems.append(_Problem(None, None, "no 'hd_mission' metadata record" +
                                     (f" (metadata records present: {names})" if names else ""), fatal=True))
        return None
    missing = [k for k in REQUIRED_META_KEYS if k not in rec]
    if missing:
        raw.problems.append(_Problem(None, None, f"hd_mission metadata lacks required keys {missing}", fatal=True))
        return None
    if rec["contract"].strip() != "1":
        raw.problems.append(_Problem(None, None, f"hd_mission contract version {rec['contract']!r} is not "
                                     "supported (this reader knows version 1)", fatal=True))
        return None
    bad = []

    def num(k, conv):
        try:
            return conv(rec[k].strip())
        except ValueError:
            bad.append(f"{k} = {rec[k]!r} is not a number")
            return float("nan")

    mi = num("mission_index", int)
    oh = num("operating_hours", float)
    gr = num("gear_ratio", float)
    kt = num("torque_constant", float)
    if bad:
        raw.problems.append(_Problem(None, None, "hd_mission metadata: " + "; ".join(bad), fatal=True))
        return None
    extra = {k: v for k, v in rec.items() if k not in REQUIRED_META_KEYS}
    meta = MissionMeta(actuator_id=rec["actuator_id"], mission_index=mi, operating_hours=oh, gear_ratio=gr,
                       torque_constant=kt, source=rec["source"].strip(), contract="1", extra=extra)
    probs = check_meta(meta)
    if probs:
        raw.problems.append(_Problem(None, None, "absurd hd_mission metadata: " + "; ".join(probs), fatal=True))
        return None
    return meta


def _order(raw: _Raw, topic: str, stamps: np.ndarray, index: np.ndarray, report_into: ReadReport | None):
    """Sort by stamp (stable), find reordered/duplicate samples; returns (order, keep mask after sort, stats)."""
    n = len(stamps)
    arrival = np.argsort(index, kind="stable")  # file order
    s_arr = stamps[arrival]
    cm = np.maximum.accumulate(s_arr) if n else s_arr
    late = s_arr < cm
    back_ns = int((cm - s_arr).max()) if n else 0
    order = arrival[np.argsort(s_arr, kind="stable")]
    s = stamps[order]
    dup = np.zeros(n, bool)
    if n > 1:
        dup[1:] = s[1:] == s[:-1]
    return order, ~dup, late, back_ns, index[arrival][late], index[order][dup]


def _js_matrix(raw: _Raw, topic: str, acc: _JSAcc, want: tuple[str, ...], fields: tuple[str, ...]):
    """Concatenate JointState groups into stamps, index and an (n, len(want)) matrix of chosen fields."""
    n_tot = sum(len(s) for s in acc.stamps)
    out = np.full((n_tot, len(want)), np.nan)
    stamps = np.empty(n_tot, np.int64)
    index = np.empty(n_tot, np.int64)
    p = 0
    missing_names: dict[str, int] = {}
    short: list[np.ndarray] = []
    for s, ix, names, pos, vel, eff in zip(acc.stamps, acc.index, acc.names, acc.pos, acc.vel, acc.eff):
        k = len(s)
        stamps[p:p + k] = s
        index[p:p + k] = ix
        arrs = {"position": pos, "velocity": vel, "effort": eff}
        for nm in dict.fromkeys(want):
            if nm not in names:
                missing_names[nm] = missing_names.get(nm, 0) + k
        for c, (nm, fld) in enumerate(zip(want, fields)):
            if nm not in names:
                continue
            j = names.index(nm)
            a = arrs[fld]
            if j < a.shape[1]:
                out[p:p + k, c] = a[:, j]
            else:
                short.append(ix)
        p += k
    for nm, k in missing_names.items():
        raw.problems.append(_Problem(topic, None, f"joint name {nm!r} missing in {k} of {n_tot} messages "
                                     f"(names must include {list(dict.fromkeys(want))})",
                                     fatal=(k == n_tot)))
    if short:
        ix = np.unique(np.concatenate(short))
        raw.problems.append(_Problem(topic, ix, "position/velocity/effort array shorter than name "
                                     "(value read as NaN)"))
    return stamps, index, out


def _limit_check(raw: _Raw, topic: str, name: str, v: np.ndarray, index: np.ndarray, lo: float, hi: float,
                 unit: str) -> np.ndarray:
    bad = ~np.isnan(v) & ~((v >= lo) & (v <= hi))
    nb = int(bad.sum())
    if nb:
        frac = nb / max(len(v), 1)
        raw.problems.append(_Problem(topic, index[bad], f"{name} beyond physical limits [{lo:g}, {hi:g}] {unit} "
                                     f"({nb} samples, e.g. {v[bad][0]!r}; read as NaN)",
                                     fatal=frac > MAX_ABSURD_FRACTION))
        v = v.copy()
        v[bad] = np.nan
    return v


#: degC: above this a winding or gearbox temperature is beyond any insulation class (H: 180 degC) and grease
KELVIN_SUSPECT_DEGC = 200.0


def _kelvin_check(raw: _Raw, rep: ReadReport, frame: str, v: np.ndarray) -> None:
    """A temperature whose median lies above :data:`KELVIN_SUSPECT_DEGC` and reads as -70..130 degC less 273.15 is
    most likely logged in kelvin (``sensor_msgs/Temperature`` is degrees Celsius): reported, suspect, not changed
    (a temperature law in (T - T_ref) does not care; a twin or threshold trained in degC does)."""
    f = v[np.isfinite(v)]
    if not len(f):
        return
    med = float(np.median(f))
    if med > KELVIN_SUSPECT_DEGC and -70.0 <= med - 273.15 <= 130.0:
        msg = (f"temperature[{frame}] has median {med:.5g} degC, beyond any winding insulation class or grease; as "
               f"kelvin it is {med - 273.15:.4g} degC: logged in kelvin? (contract: degrees Celsius)")
        raw.problems.append(_Problem(TOPIC_TEMPERATURE, None, msg))
        rep.notes.append(msg)
        rep.suspect.append(msg)


#: omega / d(theta)/dt outside this band is a unit or sign error, not a speed estimator's lag
#: (measured rigs: 0.4-1.0; rpm for rad/s gives 9.55, deg/s 57.3, a reversed sign -1).
SPEED_SCALE_BAND = (0.25, 4.0)


def _angle_resolution(theta: np.ndarray) -> float:
    """The angle's quantisation step [rad] as the log shows it: the smallest sample-to-sample change that recurs
    (the 5th percentile of the nonzero |differences|), 0 for an analogue (continuous-valued) angle, whose
    differences have no floor and whose 5th percentile sits far below its typical step. Only an encoder whose
    log repeats values (>= 20 % of the differences exactly 0) is read as quantised."""
    dth = np.abs(np.diff(theta[np.isfinite(theta)]))
    if dth.size < 20 or np.mean(dth == 0) < 0.2:
        return 0.0
    nz = dth[dth > 0]
    return float(np.percentile(nz, 5)) if nz.size else 0.0


def _consistency(raw: _Raw, rep: ReadReport, t: np.ndarray, M: np.ndarray, N: float) -> None:
    """Cross-signal checks that catch unit and sign errors of other tools (validate errors, notes).

    * omega_m, omega_f against the derivative of theta_m, theta_f (differences over ~10 ms, moving
      samples only): least-squares scale outside :data:`SPEED_SCALE_BAND`;
    * Q_red against the wind-up theta_m / N - theta_f (contract: same sign): correlation < -0.5.
    """
    n = len(t)
    if n < 20:
        return
    L = max(1, int(round(0.01 / max(float(np.median(np.diff(t))), 1e-9))))
    if n <= 4 * L:
        return
    for c_th, c_om, th_name, om_name in ((0, 2, "theta_m", "omega_m"), (1, 3, "theta_f", "omega_f")):
        d = (M[L:, c_th] - M[:-L, c_th]) / (t[L:] - t[:-L])
        om = 0.5 * (M[L:, c_om] + M[:-L, c_om])
        ok = np.isfinite(d) & np.isfinite(om)
        if ok.sum() < 50:
            continue
        # moving: above a tenth of the mission's own speed range and above the angle's resolution floor (a held or
        # parked axis whose encoder toggles between two counts has a difference quotient of pure quantisation: the
        # speed reads ~0 there, the quotient +-q / 10 ms, and their ratio is no statement about units)
        floor = 3.0 * _angle_resolution(M[:, c_th]) / float(np.median(t[L:] - t[:-L]))
        mov = ok & (np.abs(d) > max(0.1 * np.percentile(np.abs(d[ok]), 95), floor))
        if mov.sum() < 50 or not np.any(d[mov]):
            continue
        k = float(np.sum(d[mov] * om[mov]) / np.sum(d[mov] ** 2))
        # a drive's electrical speed (pole pairs x the mechanical one) beside the mechanical angle: an integer ratio
        # 2..32 to within 2 %, inside the band for 2-4 pole pairs (a speed estimate's lag gives 0.4-1.0, never that)
        pp = round(k) if math.isfinite(k) else 0
        electrical = c_om == 2 and 2 <= pp <= 32 and abs(k / pp - 1.0) < 0.02
        if not SPEED_SCALE_BAND[0] <= k <= SPEED_SCALE_BAND[1] or electrical:
            msg = (f"{om_name} is {k:.4g} x the time derivative of {th_name} over moving samples "
                   f"(contract: rad/s, the derivative of the angle in rad)"
                   f"{_speed_hint(k, om_name, th_name, pp if electrical else 0)}")
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg))
            rep.notes.append(msg)
            rep.suspect.append(msg)
    if N is None:
        return
    wu = M[:, 0] / N - M[:, 1]
    ok = np.isfinite(wu) & np.isfinite(M[:, 5])
    if ok.sum() >= 50 and np.std(wu[ok]) > 0 and np.std(M[ok, 5]) > 0:
        r = float(np.corrcoef(wu[ok], M[ok, 5])[0, 1])
        if r < -0.5:
            msg = (f"Q_red is anti-correlated with the wind-up theta_m / N - theta_f (r = {r:.2f}); the plant "
                   "transmits torque in the direction of the wind-up: torque sensor sign reversed?")
            # a warning, not an error: the contract fixes the sign of Q_red against theta_f, not against
            # the wind-up (the sign follows from the physics, not from the page)
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg, "warning"))
            rep.notes.append(msg)
            rep.suspect.append(msg)


def gear_ratio_from_encoders(t: np.ndarray, theta_m: np.ndarray, theta_f: np.ndarray) -> tuple[float, int]:
    """(N, number of increments used): least-squares slope of theta_m increments on theta_f increments
    over ~10 ms, on moving stretches only (|d theta_f| above 10 % of its 95th percentile and above
    :data:`MIN_OUTPUT_INCREMENT`); NaN when the output barely moves (fewer than 50 such increments)."""
    n = len(t)
    if n < 20:
        return float("nan"), 0
    L = max(1, int(round(0.01 / max(float(np.median(np.diff(t))), 1e-9))))
    if n <= 4 * L:
        return float("nan"), 0
    dm = theta_m[L:] - theta_m[:-L]
    df = theta_f[L:] - theta_f[:-L]
    ok = np.isfinite(dm) & np.isfinite(df)
    if ok.sum() < 50:
        return float("nan"), 0
    # moving: above 10 % of the typical stroke and above MIN_OUTPUT_INCREMENT, so encoder noise and the
    # transmission's twist (~1e-3 rad in all) cannot set the slope of a standstill
    thr = max(0.1 * np.percentile(np.abs(df[ok]), 95), MIN_OUTPUT_INCREMENT)
    mov = ok & (np.abs(df) > thr)
    k = int(mov.sum())
    if k < 50:
        return float("nan"), k
    return float(np.sum(dm[mov] * df[mov]) / np.sum(df[mov] ** 2)), k


def _nearest_factor(r: float, known: list[tuple[float, str]], tol: float) -> tuple[float, str] | None:
    """The (factor, meaning) of ``known`` nearest to the ratio ``r > 0`` on a log scale, when within ``tol``."""
    f, what = min(known, key=lambda fw: abs(math.log(r / fw[0])))
    return (f, what) if abs(math.log(r / f)) < tol else None


def _speed_hint(k: float, om_name: str, th_name: str, pole_pairs: int) -> str:
    """What a speed-to-derivative ratio ``k`` of a foreign log usually means, or "", in this order: the speed in rpm,
    deg/s or rev/s (within 15 %), a drive's electrical speed (``pole_pairs`` > 0, decided by the caller), the angle
    in degrees or revolutions (within 15 %), a reversed sign."""
    if k < 0:
        return " (opposite sign: reversed convention?)"
    if k == 0:
        return ""
    speed = _nearest_factor(k, [(60 / (2 * math.pi), f"{om_name} in rpm"), (180 / math.pi, f"{om_name} in deg/s"),
                                (1 / (2 * math.pi), f"{om_name} in rev/s")], 0.15)
    if speed is not None:
        return f" (close to {speed[0]:.4g}: {speed[1]}?)"
    if pole_pairs:
        return f" (close to {pole_pairs}: {om_name} the electrical speed of a motor with {pole_pairs} pole pairs?)"
    angle = _nearest_factor(k, [(math.pi / 180, f"{th_name} in degrees"), (2 * math.pi, f"{th_name} in revolutions")],
                            0.15)
    return f" (close to {angle[0]:.4g}: {angle[1]}?)" if angle is not None else ""


def _ratio_hint(r: float) -> str:
    """What a ratio (encoders' theta_m / theta_f over the metadata's N) of a foreign log usually means, or "".

    The usual ways another tool's angles leave the contract, each a fixed factor within 3 %: the motor angle in
    electrical radians (x the pole pairs, 2..32), in degrees or revolutions, the output angle in degrees or
    revolutions, or the sign of one encoder reversed."""
    if not math.isfinite(r) or r == 0:
        return ""
    if r < 0:
        return " (negative: one encoder's sign reversed?)"
    known = [(180 / math.pi, "theta_m in degrees"), (1 / (2 * math.pi), "theta_m in revolutions"),
             (math.pi / 180, "theta_f in degrees"), (2 * math.pi, "theta_f in revolutions")]
    known += [(float(p), f"theta_m in electrical radians of a motor with {p} pole pairs") for p in range(2, 33)]
    hit = _nearest_factor(r, known, 0.03)
    return f" ({r:.4g} x N: {hit[1]}?)" if hit is not None else ""


def _gear_ratio_check(raw: _Raw, rep: ReadReport, t: np.ndarray, M: np.ndarray, N: float) -> bool:
    """Metadata carries no checksum: compare its gear_ratio with the ratio the encoders show. Returns
    False (and reports an error + suspect) on a mismatch beyond :data:`GEAR_RATIO_TOLERANCE`."""
    n_hat, k = gear_ratio_from_encoders(t, M[:, 0], M[:, 1])
    rep.gear_ratio_encoders = n_hat
    if not math.isfinite(n_hat):
        rep.notes.append("gear_ratio not checked against the encoders: the output barely moves in this mission")
        return True
    if abs(n_hat - N) <= GEAR_RATIO_TOLERANCE * abs(N):
        return True
    msg = (f"metadata gear_ratio = {N:g} but the encoders show theta_m / theta_f = {n_hat:.4g} (slope over {k} "
           f"moving 10 ms increments; tolerance {GEAR_RATIO_TOLERANCE:.0%}): the metadata is wrong (a flipped "
           "bit, another actuator's record) or theta_m is not the motor angle" + _ratio_hint(n_hat / N) +
           "; twist, wind-up and stiffness checks skipped")
    raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg))
    rep.notes.append(msg)
    rep.suspect.append(msg)
    return False


#: a jump is a wrap when, after removing the motion its speed explains, it is a whole number of turns to within this [rad]
WRAP_TOL = 0.5


def whole_turns(step: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """The wrap rule: per step of an angle [rad], the whole number k != 0 of turns it is after the motion its speed
    explains (``moved``, the trapezoid of the two speeds), to within :data:`WRAP_TOL`; 0 where it is no such step
    (or not finite). Used by :func:`_unwrap_check` and the onboard stream (``hd_onboard.guard``)."""
    d = step - moved
    k = np.rint(d / (2.0 * math.pi))
    ok = np.isfinite(d) & (k != 0) & (np.abs(d - 2.0 * math.pi * k) < WRAP_TOL)
    return np.where(ok, k, 0.0)


def _unwrap_check(raw: _Raw, rep: ReadReport, t: np.ndarray, M: np.ndarray, N: float | None) -> None:
    """An angle logged within one turn (a single-turn encoder, modulo 2 pi; contract: unwrapped) is unwrapped, with a
    note; one whose jumps the speed cannot explain as whole turns is reported, not changed.

    Symptom and test, per angle (theta_m with omega_m, theta_f with omega_f), asked only where some step between
    neighbouring samples exceeds pi: the samples stay inside one window of 2 pi, and every step that the logged speed
    does not explain (the trapezoid of the two speeds over the step, to within :data:`WRAP_TOL`) is a whole number
    k != 0 of turns to within :data:`WRAP_TOL`. Then each
    such step loses 2 pi k (what a logger that unwrapped would have written). A wrapped angle read as it is would make
    the gear-ratio check blame the metadata ("theta_m / theta_f = 6.6") and the speed check the units ("omega_m is
    0.005 x the time derivative"), and every position effect would see the jumps. In place, on ``M``.

    The turn a wrapped log starts in is lost; with the gear ratio ``N`` the unwrapped angle is moved by whole turns to
    the other encoder's (theta_m = N theta_f up to the twist, which is far below a turn on either side), so the twist
    stays meaningful; without ``N`` it is left as the log's first turn."""
    if len(t) < 3:
        return
    unwrapped = []
    two_pi = 2.0 * math.pi
    for c_th, c_om, th_name, om_name in ((0, 2, "theta_m", "omega_m"), (1, 3, "theta_f", "omega_f")):
        th = M[:, c_th]
        fin = np.flatnonzero(np.isfinite(th))
        if len(fin) < 3:
            continue
        x = th[fin]
        step = np.diff(x)
        jump = np.flatnonzero(np.abs(step) > math.pi)
        if not len(jump):
            continue
        # every step the speed does not explain (to WRAP_TOL) is examined, not only those beyond pi: a re-zeroed
        # encoder's step of 2 rad in a wrapped log is no whole turn and makes the log not a plain single-turn one
        # (steps across a dropout, where the speed's trapezoid is no measure of the motion, only when beyond pi)
        om, tt = M[fin, c_om], t[fin]
        dts = np.diff(tt)
        across_gap = dts > 1.5 * float(np.median(dts))
        moved_all = 0.5 * (om[:-1] + om[1:]) * dts
        unexplained = (np.abs(step - moved_all) > WRAP_TOL) & ~across_gap
        jump = np.union1d(jump, np.flatnonzero(unexplained))
        k = whole_turns(step[jump], moved_all[jump])
        wraps = k != 0
        # the evidence: whole turns between neighbouring samples; a step across a dropout may be a whole turn by
        # chance (the motion during it is unknown), so it is unwrapped only beside such evidence and is none itself
        evidence = wraps & ~across_gap[jump]
        if not evidence.any():
            continue
        bounded = float(np.ptp(x)) <= two_pi * (1.0 + 1e-6) + WRAP_TOL
        if bounded and wraps.all():
            turns = np.zeros(len(step))
            turns[jump] = k
            x = x - two_pi * np.concatenate([[0.0], np.cumsum(turns)])
            M[fin, c_th] = x
            msg = (f"{th_name} is logged within one turn (modulo 2 pi; contract: unwrapped): {len(jump)} steps of a whole "
                   f"turn that {om_name} does not show; unwrapped (each such step less 2 pi k, k from the step less the "
                   f"motion {om_name} explains)")
            unwrapped.append(c_th)
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg, "warning"))
            rep.notes.append(msg)
        else:
            msg = (f"{th_name} steps by more than {om_name} explains {len(jump)} times, {int(wraps.sum())} of them by "
                   f"whole turns (a log within one turn?), but " +
                   ("not all" if bounded else f"the angle spans {float(np.ptp(x)):.4g} rad, more than one turn") +
                   ": not a plain single-turn log, left as read (contract: unwrapped)")
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg))
            rep.notes.append(msg)
            rep.suspect.append(msg)
    if unwrapped and N:
        c = 0 if 0 in unwrapped else 1  # theta_m moved to theta_f's turn when it was wrapped, else theta_f to theta_m's
        gap = N * M[:, 1] - M[:, 0] if c == 0 else M[:, 0] / N - M[:, 1]
        gap = gap[np.isfinite(gap)]
        if len(gap):
            turns = float(np.rint(np.median(gap) / (2.0 * math.pi)))
            if turns:
                M[:, c] += 2.0 * math.pi * turns
                rep.notes.append(f"{JOINT_SIGNALS[c]}: moved by {turns:+.0f} turns to the other encoder's turn "
                                 f"(N = {N:g}; a wrapped log does not say which turn it started in)")


def _spike_check(raw: _Raw, rep: ReadReport, M: np.ndarray, index: np.ndarray) -> None:
    """Bags without a CRC (unchunked, or chunk CRC 0): isolated samples that leave the line through
    their neighbours by more than :data:`SPIKE_SIGMAS` robust sigmas of the steps while the neighbours
    agree (a flipped exponent bit) are reported as errors and read as NaN."""
    if len(M) < 20:
        return
    for c, nm in enumerate(JOINT_SIGNALS):
        x = M[:, c]
        d1 = np.diff(x)
        f1 = d1[np.isfinite(d1)]
        if len(f1) < 10:
            continue
        sig = 1.4826 * float(np.median(np.abs(f1 - np.median(f1))))
        scale = float(np.nanmedian(np.abs(x))) if np.isfinite(x).any() else 0.0
        sig = max(sig, 1e-9 * max(scale, 1.0))
        a, b, m_ = x[:-2], x[2:], x[1:-1]
        dev = np.abs(m_ - 0.5 * (a + b))
        bad = (dev > SPIKE_SIGMAS * sig) & (np.abs(b - a) < 5.0 * sig + np.abs(np.median(f1)) * 2)
        bad &= np.isfinite(dev)
        nb = int(bad.sum())
        if nb:
            ii = np.flatnonzero(bad) + 1
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, index[ii],
                                         f"{nm}: {nb} isolated samples leave the line through their neighbours by "
                                         f"more than {SPIKE_SIGMAS:g} robust sigmas (e.g. {float(x[ii[0]])!r} between "
                                         f"{float(x[ii[0] - 1])!r} and {float(x[ii[0] + 1])!r}); this bag has no CRC, "
                                         "so they are taken as corrupt bytes (read as NaN)"))
            rep.notes.append(f"{nm}: {nb} isolated corrupt-looking samples read as NaN (bag without CRC)")
            M[ii, c] = np.nan


def check_mission_sequence(metas: list[tuple[str, MissionMeta]]) -> list[Violation]:
    """Across bags: per actuator, operating_hours must not decrease as mission_index grows (the same
    mission in two files, e.g. a copy, is not a finding). ``metas``: (path, meta) pairs; returns error
    violations naming the later file of each offending pair."""
    out: list[Violation] = []
    by_act: dict[str, list[tuple[int, float, str]]] = {}
    for path, m in metas:
        by_act.setdefault(m.actuator_id, []).append((int(m.mission_index), float(m.operating_hours), path))
    for act, rows in by_act.items():
        rows.sort(key=lambda r: (r[0], r[1]))
        for (i0, h0, p0), (i1, h1, p1) in zip(rows, rows[1:]):
            if i1 > i0 and h1 < h0:
                out.append(Violation(p1, None, None, f"actuator {act!r}: operating_hours {h1:g} at mission {i1} is "
                                                      f"below {h0:g} at mission {i0} ({p0}): hours must not decrease"))
    return out


def _assemble(raw: _Raw, include_sim: bool) -> Mission | None:
    path = raw.path
    rep = ReadReport(path=path, n_messages=dict(raw.counts))
    meta = _parse_meta(raw)
    # ---- joint states -----------------------------------------------------
    acc = raw.js.get(TOPIC_JOINT_STATES)
    if acc is None or not acc.stamps:
        why = "no /hd/joint_states messages" if TOPIC_JOINT_STATES not in raw.counts else \
            "/hd/joint_states could not be decoded"
        if not any(p.fatal and p.topic == TOPIC_JOINT_STATES for p in raw.problems):
            raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, why + " (required topic)", fatal=True))
        return None
    want = ("motor", "output", "motor", "output", "motor", "output")
    fields = ("position", "position", "velocity", "velocity", "effort", "effort")
    stamps, index, M = _js_matrix(raw, TOPIC_JOINT_STATES, acc, want, fields)
    if any(p.fatal for p in raw.problems):
        return None
    for c, nm in enumerate(JOINT_SIGNALS):
        lim = PHYSICAL_LIMITS[nm]
        M[:, c] = _limit_check(raw, TOPIC_JOINT_STATES, nm, M[:, c], index, -lim, lim, "SI")
    n_raw = len(stamps)
    order, keep, late, back_ns, late_idx, dup_idx = _order(raw, TOPIC_JOINT_STATES, stamps, index, rep)
    s = stamps[order][keep]
    M = M[order][keep]
    n = len(s)
    if n < 2:
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, f"only {n} distinct header.stamp values in "
                                     f"{n_raw} messages: need at least 2 samples", fatal=True))
        return None
    if n < 0.5 * n_raw:
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, f"header.stamp repeats: {n_raw - n} of {n_raw} "
                                     "messages share a stamp (is header.stamp filled in?)", fatal=True))
    d = np.diff(s)
    dt_ns = float(np.median(d))
    dt = dt_ns * 1e-9
    if late.any():
        frac = late.sum() / n_raw
        fatal = back_ns > MAX_BACKWARD_PERIODS * dt_ns or frac > MAX_REORDERED_FRACTION
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, late_idx,
                                     f"header.stamp not monotonic: {int(late.sum())} samples arrive after a "
                                     f"later stamp (largest step back {back_ns * 1e-9:.6g} s = "
                                     f"{back_ns / dt_ns:.1f} sample periods)" +
                                     ("; the stamp clock is broken, not slightly out of order" if fatal else
                                      "; re-sorted"),
                                     "error" if fatal else "warning", fatal))
        rep.n_reordered = int(late.sum())
        if not fatal:
            rep.notes.append(f"re-sorted {int(late.sum())} out-of-order joint-state samples by header.stamp "
                             f"(largest step back {back_ns * 1e-9:.3g} s)")
    if len(dup_idx):
        rep.n_duplicates = len(dup_idx)
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, dup_idx, "duplicate header.stamp (dropped, first kept)",
                                     "warning"))
        rep.notes.append(f"dropped {len(dup_idx)} joint-state messages with a duplicate header.stamp "
                         "(kept the first received)")
    fs = 1.0 / dt
    if not RATE_RANGE[0] * 0.98 <= fs <= RATE_RANGE[1] * 1.02:
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, f"sample rate {fs:.4g} Hz (median stamp step) is "
                                     f"outside the contract's {RATE_RANGE[0]:g} Hz to {RATE_RANGE[1]:g} Hz"))
        rep.notes.append(f"sample rate {fs:.4g} Hz is outside the contract range; read anyway")
    # A step is a dropout when it exceeds 1.5 periods *and* is beyond the stamp jitter: with
    # heavy jitter (e.g. +-30 % of the period, steps spread 0.4..1.6 periods) a 1.6-period step
    # is jitter, not a lost sample. Jitter scale: robust sigma (1.4826 MAD) of the steps.
    jit_ns = 1.4826 * float(np.median(np.abs(d - dt_ns)))
    is_gap = (d > 1.5 * dt_ns) & (d - dt_ns > 3.0 * jit_ns)
    missing = np.where(is_gap, np.maximum(np.rint(d / dt_ns).astype(np.int64) - 1, 1), 0)
    if jit_ns > 0.05 * dt_ns:
        rep.notes.append(f"header.stamp jitter {jit_ns / dt_ns:.0%} of the {dt * 1e3:.4g} ms period (robust "
                         f"sigma of the steps): steps up to {(dt_ns + 3.0 * jit_ns) / dt_ns:.2f} periods read "
                         "as jitter, not dropouts")
    gi = np.nonzero(missing >= 1)[0]
    rep.gaps = [(int(i + 1), int(missing[i])) for i in gi]
    big = missing > MAX_INTERP_GAP_SAMPLES
    segment = np.concatenate([[0], np.cumsum(big)]).astype(np.int32)
    if len(gi):
        tot = int(missing[gi].sum())
        raw.problems.append(_Problem(TOPIC_JOINT_STATES, None,
                                     f"{len(gi)} dropout gaps, {tot} samples missing "
                                     f"({int(big.sum())} longer than {MAX_INTERP_GAP_SAMPLES} samples)", "warning"))
        rep.notes.append(f"{len(gi)} dropout gaps ({tot} samples missing at nominal {fs:.4g} Hz) marked in "
                         f"report.gaps; not interpolated; {int(big.sum())} gaps longer than "
                         f"{MAX_INTERP_GAP_SAMPLES} samples split the mission into {int(segment[-1]) + 1} segments")
    rep.nominal_dt = dt
    _unwrap_check(raw, rep, (s - s[0]) * 1e-9, M, float(meta.gear_ratio) if meta is not None else None)
    if raw.scan.n_loose or raw.scan.n_unchecked:
        _spike_check(raw, rep, M, index[order][keep])
    ratio_ok = meta is not None and _gear_ratio_check(raw, rep, (s - s[0]) * 1e-9, M, float(meta.gear_ratio))
    if meta is not None and ratio_ok:
        tw = M[:, 1] - M[:, 0] / float(meta.gear_ratio)
        tw = tw[np.isfinite(tw)]
        if len(tw):
            rep.twist_offset = float(np.median(tw))
            if abs(rep.twist_offset) > MAX_TWIST_OFFSET:
                msg = (f"theta_f - theta_m / N has median {rep.twist_offset:.6g} rad (N = {meta.gear_ratio:g}): far "
                       f"beyond any transmission twist (> {MAX_TWIST_OFFSET:g} rad), so theta_m and theta_f have no "
                       "common zero (contract: theta_m = N theta_f + compliance); twist-based estimates (twin, "
                       "stiffness, lost motion) are meaningless until the encoders are co-referenced")
                raw.problems.append(_Problem(TOPIC_JOINT_STATES, None, msg))
                rep.notes.append(msg)
                rep.suspect.append(msg)
        _consistency(raw, rep, (s - s[0]) * 1e-9, M, float(meta.gear_ratio))
    elif meta is not None:  # a wrong N makes the twist and wind-up checks misleading: only the speed checks
        _consistency(raw, rep, (s - s[0]) * 1e-9, M, None)
    rep.n_nan = {nm: int(np.isnan(M[:, c]).sum()) for c, nm in enumerate(JOINT_SIGNALS)}
    t0 = int(s[0])
    t = (s - t0) * 1e-9
    # ---- command ------------------------------------------------------------
    t_cmd = np.zeros(0)
    theta_ref = np.zeros(0)
    cacc = raw.js.get(TOPIC_COMMAND)
    if cacc is not None and cacc.stamps:
        cs, cidx, CM = _js_matrix(raw, TOPIC_COMMAND, cacc, ("output",), ("position",))
        if any(p.fatal for p in raw.problems):
            return None
        v = _limit_check(raw, TOPIC_COMMAND, "theta_ref", CM[:, 0], cidx, -PHYSICAL_LIMITS["theta_ref"],
                         PHYSICAL_LIMITS["theta_ref"], "rad")
        order, keep, late, back_ns, late_idx, dup_idx = _order(raw, TOPIC_COMMAND, cs, cidx, None)
        if late.any():
            raw.problems.append(_Problem(TOPIC_COMMAND, late_idx, "header.stamp not monotonic (re-sorted)",
                                         "warning"))
            rep.notes.append(f"re-sorted {int(late.sum())} out-of-order command samples")
        if len(dup_idx):
            raw.problems.append(_Problem(TOPIC_COMMAND, dup_idx, "duplicate header.stamp (dropped)", "warning"))
            rep.notes.append(f"dropped {len(dup_idx)} command messages with a duplicate stamp")
        t_cmd = (cs[order][keep] - t0) * 1e-9
        theta_ref = v[order][keep]
        rep.n_nan["theta_ref"] = int(np.isnan(theta_ref).sum())
    else:
        raw.problems.append(_Problem(TOPIC_COMMAND, None, "no /hd/command messages: theta_ref is empty "
                                     "(contract topic; allowed for rigs without a position command)", "warning"))
        rep.notes.append("no /hd/command: theta_ref empty")
    # ---- temperature -----------------------------------------------------------
    temps: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    tacc = raw.temp
    if tacc.stamps:
        frames = np.concatenate([np.full(len(s_), i) for i, s_ in enumerate(tacc.stamps)])
        fr_names = tacc.frame
        ts = np.concatenate(tacc.stamps)
        tix = np.concatenate(tacc.index)
        tv = np.concatenate(tacc.value)
        tv = _limit_check(raw, TOPIC_TEMPERATURE, "temperature", tv, tix, *TEMPERATURE_RANGE, "degC")
        by_frame: dict[str, list[int]] = {}
        for i, fr in enumerate(fr_names):
            by_frame.setdefault(fr, []).append(i)
        for fr, groups in by_frame.items():
            m = np.isin(frames, groups)
            if fr not in TEMPERATURE_FRAMES:
                raw.problems.append(_Problem(TOPIC_TEMPERATURE, tix[m], f"header.frame_id {fr!r} is not one of "
                                             f"{list(TEMPERATURE_FRAMES)} (skipped)"))
                rep.notes.append(f"skipped {int(m.sum())} temperature messages with frame_id {fr!r}")
                continue
            order, keep, late, _, late_idx, dup_idx = _order(raw, TOPIC_TEMPERATURE, ts[m], tix[m], None)
            if late.any():
                rep.notes.append(f"re-sorted {int(late.sum())} out-of-order {fr} temperature samples")
            if len(dup_idx):
                rep.notes.append(f"dropped {len(dup_idx)} {fr} temperature messages with a duplicate stamp")
            temps[fr] = ((ts[m][order][keep] - t0) * 1e-9, tv[m][order][keep])
            rep.n_nan[f"temperature[{fr}]"] = int(np.isnan(temps[fr][1]).sum())
            _kelvin_check(raw, rep, fr, temps[fr][1])
    else:
        raw.problems.append(_Problem(TOPIC_TEMPERATURE, None, "no /hd/temperature messages (contract topic; "
                                     "temperature_on_t() gives NaN)", "warning"))
        rep.notes.append("no /hd/temperature: temperatures empty")
    for p in raw.problems:
        if p.topic is None and not p.fatal and p.severity == "error":
            rep.notes.append(p.problem)
    if meta is None or any(p.fatal for p in raw.problems):
        return None
    # ---- ground truth (evaluation only) -------------------------------------------
    sim: dict[str, Any] = {}
    if include_sim:
        for topic in (TOPIC_SIM_INTERNAL, TOPIC_SIM_HEALTH):
            a = raw.js.get(topic)
            if a is None or not a.stamps:
                continue
            names = list(dict.fromkeys(nm for g in a.names for nm in g))
            ss, ii, V = _js_matrix(raw, topic, a, tuple(names), ("position",) * len(names))
            order = np.argsort(ss, kind="stable")
            d_: dict[str, Any] = {"t": (ss[order] - t0) * 1e-9}
            for c, nm in enumerate(names):
                d_[nm] = V[order, c]
            if topic == TOPIC_SIM_HEALTH:
                d_ = {k: (float(v[0]) if k != "t" else float(v[0])) for k, v in d_.items()}
            sim[topic] = d_
        eff = raw.strings.get(TOPIC_SIM_EFFECTS)
        if eff:
            try:
                sim[TOPIC_SIM_EFFECTS] = json.loads(eff[-1][1])
            except (json.JSONDecodeError, RecursionError) as e:
                raise BagError(path, f"/sim/effects is not valid JSON: {e}") from None
    return Mission(meta=meta, t=t, theta_m=M[:, 0].copy(), theta_f=M[:, 1].copy(), omega_m=M[:, 2].copy(),
                   omega_f=M[:, 3].copy(), tau_m=M[:, 4].copy(), Q_red=M[:, 5].copy(), t_cmd=t_cmd,
                   theta_ref=theta_ref, temperatures=temps, t0_ns=t0, segment=segment, report=rep, sim=sim)


def _fatal_message(raw: _Raw) -> str:
    f = [p for p in raw.problems if p.fatal]
    parts = []
    for p in f:
        s = (f"{p.topic}: " if p.topic else "") + p.problem
        if p.index is not None and len(p.index):
            s += f" (message {int(p.index[0])}" + (f" and {len(p.index) - 1} more)" if len(p.index) > 1 else ")")
        parts.append(s)
    return "; ".join(parts)


def read_mission(path: str | os.PathLike, *, include_sim: bool = False) -> Mission:
    """Read one contract bag into a :class:`Mission` (SI arrays, report of every repair).

    Raises :class:`BagError` (message starts with the path) for the fatal
    problems listed in this module's docstring. ``include_sim=True`` also reads
    the ``/sim/...`` ground truth into ``Mission.sim`` (evaluation code only).
    """
    path = os.fspath(path)
    raw = _scan(path, include_sim)
    m = _assemble(raw, include_sim)
    if m is None or any(p.fatal for p in raw.problems):
        raise BagError(path, _fatal_message(raw) or "unusable bag")
    return m


def validate_bag(path: str | os.PathLike) -> list[Violation]:
    """Every contract finding for one bag: errors and warnings (see the module docstring).

    Never raises for a bad bag: a bag that cannot be opened gives one error
    violation. Per-sample findings carry the message index on their topic.
    """
    path = os.fspath(path)
    try:
        raw = _scan(path, include_sim=True)
    except BagError as e:
        return [Violation(path, None, None, e.problem)]
    try:
        _assemble(raw, include_sim=True)
    except BagError as e:
        raw.problems.append(_Problem(None, None, e.problem, fatal=True))
    out: list[Violation] = []
    for p in raw.problems:
        if p.index is None:
            out.append(Violation(path, p.topic, None, p.problem, p.severity))
        else:
            out.extend(Violation(path, p.topic, int(i), p.problem, p.severity) for i in np.sort(p.index).tolist())
    return out


# ---------------------------------------------------------------------------
# replay
# ---------------------------------------------------------------------------
_ROS_CLASSES: dict[str, Any] = {}


def _import_sensor_msgs():
    from sensor_msgs import msg

    return msg


def _import_std_msgs():
    from std_msgs import msg

    return msg


#: The only message types :func:`iter_messages` deserialises: type name -> (fixed importer, class name).
#: A bag's schema name is looked up here and never used to import anything (a schema named
#: ``evilpkg/msg/JointState`` is a foreign type, yielded as :class:`RawMessage`).
_ROS_TYPES = {
    "sensor_msgs/msg/JointState": (_import_sensor_msgs, "JointState"),
    "sensor_msgs/msg/Temperature": (_import_sensor_msgs, "Temperature"),
    "std_msgs/msg/String": (_import_std_msgs, "String"),
}


def _ros_class(type_name: str):
    """The rclpy class of a type of the fixed table (None: not in the table, or no ROS wheels)."""
    if type_name not in _ROS_TYPES:
        return None
    if type_name not in _ROS_CLASSES:
        imp, name = _ROS_TYPES[type_name]
        try:
            _ROS_CLASSES[type_name] = getattr(imp(), name)
        except Exception:  # no ROS wheels
            _ROS_CLASSES[type_name] = None
    return _ROS_CLASSES[type_name]


@dataclass(frozen=True)
class RawMessage:
    """A message of a type outside the reader's fixed table: its bytes and its schema, undecoded."""

    type_name: str
    schema_encoding: str
    schema: bytes
    data: bytes


def iter_messages(path: str | os.PathLike, topics: Iterable[str] | None = None, *, ros: bool = True
                  ) -> Iterator[tuple[str, int, int, Any]]:
    """Yield ``(topic, stamp_ns, log_time_ns, message)`` in log-time order, streaming.

    ``message`` is the real ROS class instance (``sensor_msgs.msg.JointState``
    ...) deserialised by rclpy's C serializer when the ROS wheels are present
    and ``ros`` is true, else an ``mcap-ros2-support`` dynamic object with the
    same fields. ``stamp_ns`` is ``header.stamp`` for messages with a header,
    else the log time. Order: sorted within each chunk and merged across
    chunks whose time ranges overlap their neighbours (a bag whose chunks
    overlap by more than one chunk is yielded in near, not exact, order).
    Types outside the reader's fixed table (JointState, Temperature, String) are
    never imported nor decoded: they come as :class:`RawMessage` (bytes and
    schema). A message above :data:`MAX_MESSAGE_BYTES` raises :class:`BagError`.
    """
    path = os.fspath(path)
    want = set(topics) if topics is not None else None
    scan = McapScan()
    deser = None
    if ros:
        try:
            from rclpy.serialization import deserialize_message as deser  # noqa: N813
        except Exception:
            deser = None
    heap: list[tuple[int, int, str, int, Any]] = []
    seq = 0

    def decode(topic: str, schema, data: bytes):
        typ = cdr.normalise_type(schema.name)
        if typ not in cdr.SCHEMAS or schema.encoding != "ros2msg":
            return RawMessage(schema.name, schema.encoding, schema.data, data)
        cap = MAX_MESSAGE_BYTES.get(typ, 0)
        if len(data) > cap:
            raise BagError(path, f"{topic}: a {typ} message of {len(data)} bytes is above the cap of {cap} bytes "
                                 "(MAX_MESSAGE_BYTES)")
        cls = _ros_class(typ) if deser is not None else None
        if cls is not None:
            return deser(data, cls)
        return cdr.generic_decoder(typ)(data)

    try:
        for block in scan_mcap(path, scan):
            if len(block.channel) == 0:
                continue
            lo = int(block.log_time.min())
            while heap and heap[0][0] <= lo:
                lt, _, topic, st, msg = heapq.heappop(heap)
                yield topic, st, lt, msg
            order = np.argsort(block.log_time, kind="stable")
            for i in order.tolist():
                ch = scan.channels.get(int(block.channel[i]))
                if ch is None or (want is not None and ch.topic not in want):
                    continue
                schema = scan.schemas.get(ch.schema_id)
                if schema is None:
                    continue
                s0 = int(block.start[i])
                data = block.buf[s0:s0 + int(block.length[i])].tobytes()
                msg = decode(ch.topic, schema, data)
                hdr = None if isinstance(msg, RawMessage) else getattr(msg, "header", None)
                lt = int(block.log_time[i])
                st = int(hdr.stamp.sec) * 1_000_000_000 + int(hdr.stamp.nanosec) if hdr is not None else lt
                heapq.heappush(heap, (lt, seq, ch.topic, st, msg))
                seq += 1
    except McapFormatError as e:
        raise BagError(path, str(e)) from None
    except BagError:
        raise
    except Exception as e:  # rclpy / generic decoder on garbage bytes
        raise BagError(path, f"undecodable message data ({type(e).__name__}: {e})") from None
    while heap:
        lt, _, topic, st, msg = heapq.heappop(heap)
        yield topic, st, lt, msg


def bag_summary(path: str | os.PathLike) -> dict[str, Any]:
    """Topics, counts, rates, duration and metadata of a bag (for ``hdphm inspect``)."""
    path = os.fspath(path)
    scan = McapScan()
    per: dict[str, dict[str, Any]] = {}
    try:
        for block in scan_mcap(path, scan):
            for cid in np.unique(block.channel).tolist():
                ch = scan.channels.get(cid)
                if ch is None:
                    continue
                lt = block.log_time[block.channel == cid]
                d = per.setdefault(ch.topic, {"type": scan.schemas[ch.schema_id].name if ch.schema_id in
                                              scan.schemas else "?", "count": 0, "t0": math.inf, "t1": -math.inf})
                d["count"] += len(lt)
                d["t0"] = min(d["t0"], int(lt.min()))
                d["t1"] = max(d["t1"], int(lt.max()))
    except McapFormatError as e:
        raise BagError(path, str(e)) from None
    for d in per.values():
        span = (d["t1"] - d["t0"]) * 1e-9
        d["duration_s"] = span
        d["rate_hz"] = (d["count"] - 1) / span if span > 0 else float("nan")
    return {"path": path, "profile": scan.profile, "library": scan.library, "topics": per,
            "metadata": scan.metadata, "complete": scan.complete,
            "issues": [i.problem for i in scan.issues]}
