"""What the onboard node reports on ``/diagnostics`` (pure: the content of each status; the node only
turns the tuples ``(name, level, message, hardware_id, values)`` into ``DiagnosticStatus`` messages).

Stable names (``docs/INTERFACES.md``): ``hdphm/onboard/fault`` (overall level, onset, twin),
``hdphm/onboard/residual/<channel>`` (EWMA against its lines), ``hdphm/onboard/stiffness`` and
``/friction`` (the monitors), ``hdphm/onboard/input/<topic>`` (per contract topic: counts, input
conditioning, STALE when missing or behind the joint states).
"""

from __future__ import annotations

import math
from typing import Any

from hd_onboard.detectors.levels import LEVEL_NAMES, STALE
from hd_ros.topics import CONTRACT_TOPICS, TOPIC_JOINT_STATES

Status = tuple[str, int, str, str, dict[str, Any]]


def input_status(core, topic: str, hardware_id: str, n_msgs: dict, last_stamp: dict, n_bad: int,
                 stale_js: bool, stale_timeout_s: float) -> Status:
    """``hdphm/onboard/input/<topic>``: message count; for joint states the core's input conditioning."""
    name = "hdphm/onboard/input" + topic[3:].replace("/", "_").replace("_", "/", 1)
    js_last = last_stamp[TOPIC_JOINT_STATES]
    last = last_stamp[topic]
    vals: dict[str, Any] = {"messages": n_msgs[topic]}
    if topic == TOPIC_JOINT_STATES:
        h = core.health
        vals.update(samples=h.n_samples, dropped_out_of_order=h.n_dropped_order, nan_samples=h.n_nan,
                    gaps=h.n_gaps, missing_samples=h.n_missing, twin_resets=h.n_resets, undecodable=n_bad)
        if stale_js:
            return name, STALE, f"no joint states for {stale_timeout_s} s", hardware_id, vals
        lev = 1 if (h.n_nan or h.n_gaps or h.n_dropped_order or n_bad) else 0
        msg = "ok" if not lev else "conditioning active (NaN / gaps / out-of-order, see values)"
        lev_i, msg_i = core.input_status()
        if lev_i:
            lev, msg = max(lev, lev_i), msg_i + ("" if msg == "ok" else "; " + msg)
        vals["input_problems"] = ",".join(core.input_notes)
        return name, lev, msg[:400], hardware_id, vals
    if js_last is not None and (last is None or (js_last - last) * 1e-9 > stale_timeout_s):
        return name, STALE, "missing" if last is None else "stale (joint-state time moved on)", hardware_id, vals
    return name, 0, "ok", hardware_id, vals


def onboard_statuses(core, meta: dict, hardware_id: str, n_msgs: dict, last_stamp: dict, n_bad: int,
                     stale_js: bool, stale_timeout_s: float) -> list[Status]:
    """Every status of one onboard report: fault, residual channels, monitors, inputs."""
    hid = hardware_id or "unknown"
    sts: list[Status] = []
    lev = STALE if stale_js else core.level
    msg = LEVEL_NAMES[lev] if core.onset_ns is None else f"{LEVEL_NAMES[lev]}; first flag at stamp {core.onset_ns * 1e-9:.3f}"
    sts.append(("hdphm/onboard/fault", lev, msg, hid,
                {"mission_index": meta.get("mission_index", ""), "twin": core.expected.kind,
                 "twin_fallback": core.fallback_reason, "twin_version": core.expected.version,
                 "onset_stamp_s": (core.onset_ns or 0) * 1e-9}))
    for c, d in core.detectors.items():
        th = d.threshold
        lev_c = 0
        if math.isfinite(d.e) and abs(d.e) > th.h_error:
            lev_c = 2
        elif math.isfinite(d.e) and abs(d.e) > th.h_warn:
            lev_c = 1
        sts.append((f"hdphm/onboard/residual/{c}", lev_c, "calibrating" if not core.calibrated else LEVEL_NAMES[lev_c], hid,
                    {"ewma": d.e, "h_warn": th.h_warn, "h_error": th.h_error, "mu": th.mu, "sigma": th.sigma,
                     "threshold_source": th.source}))
    for name, st in (("stiffness", core.stiffness_status()), ("friction", core.friction_status())):
        lev_m = int(st["level"])
        sts.append((f"hdphm/onboard/{name}", lev_m, f"{LEVEL_NAMES[lev_m]}; reference {st['reference']}",
                    hid, {k: v for k, v in st.items() if k != "level"}))
    for t in CONTRACT_TOPICS:
        sts.append(input_status(core, t, hardware_id, n_msgs, last_stamp, n_bad, stale_js, stale_timeout_s))
    return sts
