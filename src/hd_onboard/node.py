"""Onboard node (real-time module): contract topics in; residuals, flags, features out.

A thin rclpy shell over :class:`hd_onboard.core.OnboardCore`. Subscriptions
take raw CDR and drain their whole queue per callback, so the core sees
blocks (see ``hd_ros.convert.take_all``).

Subscribes: ``/hd/joint_states``, ``/hd/command``, ``/hd/temperature``
(sensor QoS), ``/hd/mission`` (JSON ``hd_mission`` metadata, latched: a new
mission resets the core; hardware_id = its actuator_id), ``/hd/twin/state``
(latched JSON: twin parameters, model version, per-actuator thresholds and
stiffness/friction monitor references: a ground reference for this node's
actuator wins over the warm-up's, status ``reference`` = "ground").
Publishes: ``/hd/onboard/residuals`` (Float64MultiArray rows, columns
``hd_onboard.core.RESIDUAL_COLUMNS``, one message per processed block),
``/hd/onboard/features`` (one row per closed window: residual statistics and
features), ``/diagnostics`` (stable names ``hdphm/onboard/...``, see
``docs/INTERFACES.md``) on every level change and every
``diag_period_s`` of sample time, and STALE when joint states stop for
``stale_timeout_s`` of wall time (temperature / command are STALE when
joint-state time advanced ``stale_timeout_s`` past their last sample).
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

import hd_ros as ru

NODE_NAME = "onboard"

PARAMS: dict[str, Any] = {
    "actuator_id": "",  # hardware_id until /hd/mission says otherwise ("" -> header.frame_id or "unknown")
    "gear_ratio": 0.0,  # N; 0 -> from /hd/mission or the twin parameters
    "model_dir": "",  # trained twin (ONNX); "" -> physics-only stand-in
    # directories a twin state's model_dir may lie in (os.pathsep-separated; + parent of model_dir, $HDPHM_MODEL_ROOTS)
    "model_roots": "",
    "diag_period_s": 0.5,  # s of sample time between periodic /diagnostics
    "stale_timeout_s": 2.0,  # s
    "max_block": 2000,  # samples per core call
    "short_path_max": 32,  # a callback with at most this many samples uses the per-sample short path
    "residual_rows": 100,  # residual rows per /hd/onboard/residuals message (sooner on a level change)
    "feature_thread": True,  # window statistics/features in a worker thread (never delays a flag)
    "rt_thread": False,  # joint states on their own node + executor thread (lowest latency; not for in-process replay)
    "rt_priority": 0,  # 1-99: the joint-state thread (rt_thread) runs SCHED_FIFO at this priority (0: normal)
    "latency_probe": False,  # bench only: record wall-clock now - header.stamp per sample (stamps must be wall time)
}


def _config_params() -> dict[str, Any]:
    """Every :class:`hd_onboard.core.OnboardConfig` field as a node parameter, with the core's default
    (one source for detection settings: the node never carries its own copy of them)."""
    import dataclasses

    from hd_onboard.core import OnboardConfig

    return {f.name: f.default for f in dataclasses.fields(OnboardConfig)}


PARAMS.update(_config_params())


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True):
    """Build the onboard node (a managed node, configured and activated unless ``autostart`` is False)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64MultiArray, String

    from hd_onboard.core import CHANNELS, RESIDUAL_COLUMNS, OnboardConfig, OnboardCore
    from hd_onboard.detector import LEVEL_NAMES, ChannelThreshold, OK, STALE
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    from hd_ros.diagnostics import diag_status
    from hd_ros.managed import ManagedNode, bring_up

    class OnboardNode(ManagedNode):
        def __init__(self):
            super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)
            self._rt = None
            self._pool = None

        def configure(self):
            self.cfg = OnboardConfig(**{k: self.p[k] for k in OnboardConfig.__dataclass_fields__ if k in self.p}).validate()
            self.twin_params = ph.TwinParams.from_yaml()
            self.twin_state: dict = {}
            self.thresholds_all: dict[str, dict[str, ChannelThreshold]] = {}
            self.references_all: dict[str, dict[str, Any]] = {}  # actuator -> {"stiffness"/"friction": reference}
            self.hardware_id = self.p["actuator_id"] or ""
            self.meta: dict = {}
            self.core = None
            self.n_msgs = {t: 0 for t in ru.CONTRACT_TOPICS}  # decoded messages
            self.n_taken = {t: 0 for t in ru.CONTRACT_TOPICS}  # messages taken from DDS (decodable or not)
            self.n_mission_msgs = 0  # /hd/mission messages taken
            self.n_bad = 0
            self.last_wall = {t: None for t in ru.CONTRACT_TOPICS}
            self.last_stamp = {t: None for t in ru.CONTRACT_TOPICS}
            self.last_diag_t = -math.inf
            self.level = OK
            self.latency_s: list[float] = []  # arrival -> flag decision, per block (bench)
            self.n_published = {ru.TOPIC_RESIDUALS: 0, ru.TOPIC_FEATURES: 0, ru.TOPIC_DIAGNOSTICS: 0}
            self.errors: list[str] = []
            self.input_problems: list[tuple[str, int, str]] = []  # (key, level, message): OnboardCore input notes
            self.latency_ns: list[int] = []  # latency_probe: per sample, decision wall time - header.stamp
            self._pending_feat: deque = deque()  # futures of window rows, in window order
            self._pool = (ThreadPoolExecutor(1, thread_name_prefix="onboard-features", initializer=_normal_priority)
                          if self.p["feature_thread"] else None)
            if self._pool is not None and sys.getswitchinterval() > 5e-4:
                # the worker holds the GIL at most this long when a sample arrives (default 5 ms)
                sys.setswitchinterval(5e-4)
            self.flags: list[tuple[str, int, int, str]] = []  # (actuator, stamp_ns, level, reason)
            self.pub_res = self.create_publisher(Float64MultiArray, ru.TOPIC_RESIDUALS, ru.topic_qos(ru.TOPIC_RESIDUALS))
            self.pub_feat = self.create_publisher(Float64MultiArray, ru.TOPIC_FEATURES, ru.topic_qos(ru.TOPIC_FEATURES))
            self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
            self._lock = threading.RLock()  # the core is shared by the joint-state thread and the others
            self._rt = None
            if self.p["rt_thread"]:
                # joint states alone in a wait set (a few entities instead of all the node's): the executor's
                # per-wake cost, not the core, dominates the arrival -> flag latency at 1 kHz
                self._rt_node = Node(NODE_NAME + "_rt", context=context, start_parameter_services=False)
                self.sub_js = self._rt_node.create_subscription(JointState, ru.TOPIC_JOINT_STATES, self._on_js_locked,
                                                                ru.qos("sensor"), raw=True)
                self._rt_exec = ru.make_executor(context)
                self._rt_exec.add_node(self._rt_node)
                self._rt_stop = threading.Event()
                self._rt = threading.Thread(target=self._rt_spin, name="onboard-joint-states", daemon=True)
            else:
                self.sub_js = self.create_subscription(JointState, ru.TOPIC_JOINT_STATES, self._on_js, ru.qos("sensor"), raw=True)
            self.sub_cmd = self.create_subscription(JointState, ru.TOPIC_COMMAND, self._on_cmd, ru.qos("sensor"), raw=True)
            self.sub_tmp = self.create_subscription(Temperature, ru.TOPIC_TEMPERATURE, self._on_temp, ru.qos("sensor"), raw=True)
            self.sub_mission = self.create_subscription(String, ru.TOPIC_MISSION, self._on_mission, ru.mission_sub_qos())
            self._t_start = time.monotonic()
            self.create_subscription(String, ru.TOPIC_TWIN_STATE, self._on_twin, ru.qos("latched"))
            self.create_timer(max(0.1, self.p["stale_timeout_s"] / 4), self._on_timer)
            self._new_core()
            self.get_logger().info(f"onboard up: twin={self.core.expected.kind} {self.core.expected.version}")
            ru.contain_callbacks(self, "hdphm/onboard")  # no exception of a callback stops the node
            if self._rt is not None:
                ru.contain_callbacks(self._rt_node, "hdphm/onboard")
                self._rt.start()

        def _rt_spin(self):
            prio = int(self.p["rt_priority"])
            if prio:
                why = ru.set_thread_realtime(prio)
                if why:
                    self.get_logger().warning(f"joint-state thread not real-time: {why}")
            while not self._rt_stop.is_set() and self.context.ok():
                try:
                    self._rt_exec.spin_once(timeout_sec=0.1)
                except Exception as e:  # noqa: BLE001 - shutdown races end the thread quietly
                    if not self._rt_stop.is_set() and self.context.ok():
                        self.get_logger().error(f"joint-state thread: {type(e).__name__}: {e}")
                    return

        def _on_js_locked(self, first):
            if not self.is_active:  # the joint-state thread's own node is not gated by the lifecycle
                return
            with self._lock:
                self._on_js(first)

        # ---- core management --------------------------------------------------
        def _new_core(self):
            N = float(self.meta.get("gear_ratio") or self.p["gear_ratio"] or self.twin_params.N)
            params = self.twin_params.with_meta(gear_ratio=N)
            model_dir = self.twin_state.get("model_dir") or self.p["model_dir"]
            # rate unknown until the core has measured it (it then configures the twin or falls back, noted)
            exp = make_expected(model_dir, params, fs_hz=self.cfg.nominal_fs or None,
                                log=lambda s: self.get_logger().warning(s))
            if getattr(exp, "fallback_reason", ""):
                self.input_problems.append(("twin_load", 2, exp.fallback_reason))
                self._error(exp.fallback_reason)
            self.core = OnboardCore(exp, params, None, self.thresholds_all.get(self.hardware_id), self.cfg,
                                    feature_fn=_feature_fn(self.meta, N))
            self._apply_references(self.core)
            self.core.defer_windows = True
            self.last_diag_t = -math.inf
            self.level = OK

        def _on_mission(self, msg):
            self.n_mission_msgs += 1
            with self._lock:
                return self._on_mission_impl(msg)

        def _on_mission_impl(self, msg):
            try:
                from hd_twin.state import check_mission

                meta = check_mission(ru.parse_json_msg(msg, ru.TOPIC_MISSION), ru.TOPIC_MISSION)
            except (ValueError, TypeError) as e:
                self._error(f"{ru.TOPIC_MISSION}: {e}")
                return
            self._close_mission()
            self.meta = meta
            self.hardware_id = str(meta.get("actuator_id") or self.hardware_id or "unknown")
            self._new_core()
            self.get_logger().debug(f"mission {meta.get('mission_index')} of {self.hardware_id}: core reset")

        def _poll_mission(self):
            sub = self.sub_mission
            with sub.handle:
                r = sub.handle.take_message(sub.msg_type, sub.raw)
            if r is not None:
                self._on_mission(r[0])

        def _close_mission(self):
            """End of the current mission: its last window and every pending row are published (in order)."""
            if self.core is not None:
                self.core.end_mission()
                self._report_input()
                self._flush_rows()
                self.core.flush()
                self._submit_windows(final=True)
                self._drain_windows(wait=True)

        def close_mission(self):
            """Public: close the current mission now (end of a replay; a live driver's /hd/mission does it too)."""
            self._close_mission()

        def _submit_windows(self, final: bool = False):
            from hd_onboard.core import window_row

            jobs = self.core.take_window_jobs()
            mi = _float_or_nan(self.meta.get("mission_index"))
            fn = self.core.feature_fn
            for k, job in enumerate(jobs):
                last = final and k == len(jobs) - 1

                def work(job=job, last=last):
                    row = window_row(job, fn)
                    if row is not None:
                        row["mission_index"] = mi
                        row["final"] = 1.0 if last else 0.0
                    return row

                if self._pool is None:
                    self._pending_feat.append(_Done(work()))
                else:
                    self._pending_feat.append(self._pool.submit(work))

        def _drain_windows(self, wait: bool = False):
            rows = []
            while self._pending_feat and (wait or self._pending_feat[0].done()):
                try:
                    r = self._pending_feat.popleft().result()
                except Exception as e:  # noqa: BLE001 - a feature failure is reported, monitoring goes on
                    self.get_logger().error(f"window features failed: {type(e).__name__}: {e}")
                    continue
                if r is not None:
                    rows.append(r)
            if rows:
                self._publish_windows(rows)

        def _flush_rows(self):
            tab = self.core.take_rows()
            if len(tab):
                self.pub_res.publish(ru.pack_table(RESIDUAL_COLUMNS, tab))
                self.n_published[ru.TOPIC_RESIDUALS] += 1

        def _on_twin(self, msg):
            with self._lock:
                return self._on_twin_impl(msg)

        def _on_twin_impl(self, msg):
            try:
                from hd_twin import state as sv

                st = sv.parse_json(msg.data, ru.TOPIC_TWIN_STATE, sv.MAX_STATE_BYTES)
                if st.get("model_dir"):  # an ONNX file is loaded from it: only inside the model roots
                    sv.check_model_dir(st["model_dir"], sv.model_roots(self.p.get("model_roots", ""), self.p["model_dir"]),
                                       f"{ru.TOPIC_TWIN_STATE} model_dir")
                for k in ("thresholds", "references"):
                    if st.get(k) is not None:
                        sv.check_per_actuator(st[k], f"{ru.TOPIC_TWIN_STATE} {k}")
                params = ph.TwinParams.from_dict(st.get("params", {}), where=ru.TOPIC_TWIN_STATE) if st.get("params") else self.twin_params
                ths = {}
                for act, chans in (st.get("thresholds") or {}).items():
                    ths[act] = {c: ChannelThreshold.from_dict(v, f"{ru.TOPIC_TWIN_STATE} thresholds[{act}][{c}]")
                                for c, v in chans.items() if c in CHANNELS}
                refs = _parse_references(st.get("references") or {}, ru.TOPIC_TWIN_STATE)
            except ValueError as e:
                self._error(f"twin update refused: {e}")
                return
            model_changed = (st.get("model_dir") or "") != (self.twin_state.get("model_dir") or "")
            old_refs = self.references_all.get(self.hardware_id)
            self.twin_state, self.twin_params, self.thresholds_all, self.references_all = st, params, ths, refs
            if model_changed and self.core is not None and self.core.last_ns is None:
                self._new_core()
            elif self.core is not None:
                self.core.set_params(params)
                if self.hardware_id in ths:
                    self.core.set_thresholds(ths[self.hardware_id])
                if refs.get(self.hardware_id) != old_refs:  # a new reference restarts that monitor's moments
                    self._apply_references(self.core)
            self.get_logger().info(f"twin state revision {st.get('revision')} applied")

        def _apply_references(self, core):
            """This actuator's ground references (if any) to ``core``, exactly as its thresholds."""
            refs = self.references_all.get(self.hardware_id) or {}
            if "stiffness" in refs:
                core.set_stiffness_reference(refs["stiffness"])
            if "friction" in refs:
                core.set_friction_reference(refs["friction"])

        def _report_input(self):
            """New input problems of the core (twin refused / replaced, encoder zero, units, short mission):
            logged, kept in :attr:`input_problems`, published once on ``hdphm/onboard/input`` at their level
            (ERROR ones also in :attr:`errors`) and then carried by ``hdphm/onboard/input/joint_states``."""
            for key, lev, msg in self.core.take_input_notes():
                self.input_problems.append((key, lev, msg))
                text = f"{ru.TOPIC_JOINT_STATES}: {msg}"
                if lev >= 2:
                    self._error(text)
                else:
                    self.get_logger().warning(text)
                    self._publish_diag([diag_status("hdphm/onboard/input", lev, text[:200],
                                                    self.hardware_id or "unknown", {"problem": key})])

        def _error(self, text: str):
            self.errors.append(text)
            self.get_logger().error(text)
            self._publish_diag([diag_status("hdphm/onboard/input", 2, text[:200], self.hardware_id or "unknown", {})])

        # ---- inputs -----------------------------------------------------------
        def _on_js(self, first):
            t_arrival = time.perf_counter()
            msgs = ru.take_all(self.sub_js, first)
            n = len(msgs)
            self.n_taken[ru.TOPIC_JOINT_STATES] += n
            if n > int(self.p["short_path_max"]):
                stamps, V, frame, problems = ru.decode_joint_states(msgs)
            else:
                stamps = np.empty(n, np.int64)
                V = np.full((n, 6), np.nan)
                ok = np.ones(n, bool)
                frame, problems = "", []
                for i, b in enumerate(msgs):
                    try:
                        s, fr, names, pos, vel, eff = ru.decode_joint_state(b)
                    except ru.CdrError as e:
                        ok[i] = False
                        problems.append(str(e))
                        continue
                    stamps[i] = s
                    if len(pos) >= 2:
                        V[i, 0:2] = pos[:2]
                    if len(vel) >= 2:
                        V[i, 2:4] = vel[:2]
                    if len(eff) >= 2:
                        V[i, 4:6] = eff[:2]
                    frame = frame or fr
                if not ok.all():
                    stamps, V = stamps[ok], V[ok]
            for e in problems:
                self.n_bad += 1
                if self.n_bad <= 3:
                    self._error(f"{ru.TOPIC_JOINT_STATES}: {e}")
            if not self.meta:  # a (re)started node: the latched mission may be queued behind the samples
                self._poll_mission()
            if not self.hardware_id and frame:
                self.hardware_id = frame
            self.n_msgs[ru.TOPIC_JOINT_STATES] += len(stamps)
            self.last_wall[ru.TOPIC_JOINT_STATES] = time.monotonic()
            core = self.core
            n_ok = len(stamps)
            if n_ok <= int(self.p["short_path_max"]):
                probe = self.p["latency_probe"]
                for s_, v_ in zip(stamps.tolist(), V.tolist()):
                    lev = core.push_one(s_, v_)
                    if lev != self.level:
                        self._after_samples(force_rows=True)
                    if probe:
                        self.latency_ns.append(time.time_ns() - s_)
            else:
                mb = int(self.p["max_block"])
                for a in range(0, n_ok, mb):
                    r = core.push(stamps[a:a + mb], V[a:a + mb])
                    if len(r.table):
                        core.rows.extend(r.table)
                    core.events.extend(r.events)
                    core.windows.extend(r.windows)
                    self._after_samples(force_rows=True)
            if n_ok:
                self.last_stamp[ru.TOPIC_JOINT_STATES] = int(core.last_ns) if core.last_ns is not None else None
            self._after_samples()
            self.latency_s.append(time.perf_counter() - t_arrival)

        def _after_samples(self, force_rows: bool = False):
            """Publish what the core produced: flags first, then rows, diagnostics, windows."""
            core = self.core
            self._report_input()
            for s, lev, why in core.take_events():
                self.flags.append((self.hardware_id, s, lev, why))
                self.get_logger().warning(f"{self.hardware_id}: {LEVEL_NAMES[lev]} at stamp {s * 1e-9:.3f} s ({why})")
            t_now = core.last_ns * 1e-9 if core.last_ns is not None else 0.0
            changed = core.level != self.level
            if changed or t_now - self.last_diag_t >= self.p["diag_period_s"]:
                self.level = core.level
                self.last_diag_t = t_now
                self._publish_status()
            if changed or force_rows or len(core.rows) >= int(self.p["residual_rows"]):
                self._flush_rows()
            if core.window_jobs:
                self._submit_windows()
            if self._pending_feat:
                self._drain_windows()

        def _publish_windows(self, windows):
            keys = sorted({k for w in windows for k in w})
            rows = np.array([[float(w.get(k, math.nan)) for k in keys] for w in windows])
            self.pub_feat.publish(ru.pack_table(keys, rows))
            self.n_published[ru.TOPIC_FEATURES] += 1

        def _on_cmd(self, first):
            with self._lock:
                return self._on_cmd_impl(first)

        def _on_cmd_impl(self, first):
            msgs = ru.take_all(self.sub_cmd, first)
            self.n_taken[ru.TOPIC_COMMAND] += len(msgs)
            stamps, V, _, problems = ru.decode_joint_states(msgs)  # column 0: position[0] = theta_ref
            for e in problems:
                self._error(f"{ru.TOPIC_COMMAND}: {e}")
            self.n_msgs[ru.TOPIC_COMMAND] += len(stamps)
            if len(stamps):
                self.last_stamp[ru.TOPIC_COMMAND] = int(stamps[-1])
            has = np.flatnonzero(~np.isnan(V[:, 0]))
            if len(has):  # the core keeps the latest reference only; a command without a position is counted
                i = int(has[-1])
                self.core.push_command(int(stamps[i]), float(V[i, 0]))
            self.last_wall[ru.TOPIC_COMMAND] = time.monotonic()

        def _on_temp(self, first):
            with self._lock:
                return self._on_temp_impl(first)

        def _on_temp_impl(self, first):
            msgs = ru.take_all(self.sub_tmp, first)
            self.n_taken[ru.TOPIC_TEMPERATURE] += len(msgs)
            for b in msgs:
                try:
                    s, frame, v = ru.decode_temperature(b)
                except ru.CdrError as e:
                    self._error(f"{ru.TOPIC_TEMPERATURE}: {e}")
                    continue
                self.n_msgs[ru.TOPIC_TEMPERATURE] += 1
                self.last_stamp[ru.TOPIC_TEMPERATURE] = s
                if frame == "gearbox" or self.meta.get("_temp_frame") in (None, frame):
                    self.meta["_temp_frame"] = frame
                    self.core.push_temperature(s, v)
            self.last_wall[ru.TOPIC_TEMPERATURE] = time.monotonic()

        # ---- diagnostics ------------------------------------------------------
        def _input_status(self, topic, stale_js: bool):
            name = "hdphm/onboard/input" + topic[3:].replace("/", "_").replace("_", "/", 1)
            js_last = self.last_stamp[ru.TOPIC_JOINT_STATES]
            last = self.last_stamp[topic]
            n = self.n_msgs[topic]
            vals = {"messages": n}
            if topic == ru.TOPIC_JOINT_STATES:
                h = self.core.health
                vals.update(samples=h.n_samples, dropped_out_of_order=h.n_dropped_order, nan_samples=h.n_nan,
                            gaps=h.n_gaps, missing_samples=h.n_missing, twin_resets=h.n_resets, undecodable=self.n_bad)
                if stale_js:
                    return diag_status(name, STALE, f"no joint states for {self.p['stale_timeout_s']} s", self.hardware_id, vals)
                lev = 1 if (h.n_nan or h.n_gaps or h.n_dropped_order or self.n_bad) else 0
                msg = "ok" if not lev else "conditioning active (NaN / gaps / out-of-order, see values)"
                lev_i, msg_i = self.core.input_status()
                if lev_i:
                    lev, msg = max(lev, lev_i), msg_i + ("" if msg == "ok" else "; " + msg)
                vals["input_problems"] = ",".join(self.core.input_notes)
                return diag_status(name, lev, msg[:400], self.hardware_id, vals)
            if js_last is not None and (last is None or (js_last - last) * 1e-9 > self.p["stale_timeout_s"]):
                return diag_status(name, STALE, "missing" if last is None else "stale (joint-state time moved on)", self.hardware_id, vals)
            return diag_status(name, 0, "ok", self.hardware_id, vals)

        def _publish_status(self, stale_js: bool = False):
            if not self.hardware_id and time.monotonic() - self._t_start < self.p["stale_timeout_s"]:
                return  # neither /hd/mission nor a frame_id named the actuator yet: no status under "unknown"
            core = self.core
            hid = self.hardware_id or "unknown"
            sts = []
            for c, d in core.detectors.items():
                th = d.threshold
                lev_c = 0
                if np.isfinite(d.e) and abs(d.e) > th.h_error:
                    lev_c = 2
                elif np.isfinite(d.e) and abs(d.e) > th.h_warn:
                    lev_c = 1
                sts.append(diag_status(f"hdphm/onboard/residual/{c}", lev_c, "calibrating" if not core.calibrated else LEVEL_NAMES[lev_c], hid,
                                       {"ewma": d.e, "h_warn": th.h_warn, "h_error": th.h_error, "mu": th.mu, "sigma": th.sigma,
                                        "threshold_source": th.source}))
            lev = STALE if stale_js else core.level
            msg = LEVEL_NAMES[lev] if core.onset_ns is None else f"{LEVEL_NAMES[lev]}; first flag at stamp {core.onset_ns * 1e-9:.3f}"
            sts.insert(0, diag_status("hdphm/onboard/fault", lev, msg, hid,
                                      {"mission_index": self.meta.get("mission_index", ""), "twin": core.expected.kind,
                                       "twin_fallback": core.fallback_reason,
                                       "twin_version": core.expected.version, "onset_stamp_s": (core.onset_ns or 0) * 1e-9}))
            for name, st in (("stiffness", core.stiffness_status()), ("friction", core.friction_status())):
                lev_m = int(st["level"])
                sts.append(diag_status(f"hdphm/onboard/{name}", lev_m, f"{LEVEL_NAMES[lev_m]}; reference {st['reference']}",
                                       hid, {k: v for k, v in st.items() if k != "level"}))
            for t in ru.CONTRACT_TOPICS:
                sts.append(self._input_status(t, stale_js))
            self._publish_diag(sts)

        def _publish_diag(self, statuses):
            a = DiagnosticArray()
            a.header.stamp = self.get_clock().now().to_msg()
            a.status = statuses
            self.pub_diag.publish(a)
            self.n_published[ru.TOPIC_DIAGNOSTICS] += 1

        def _on_timer(self):
            with self._lock:
                return self._on_timer_impl()

        def _on_timer_impl(self):
            if self.core is not None and len(self.core.rows):
                self._flush_rows()
            if self._pending_feat:
                self._drain_windows()
            lw = self.last_wall[ru.TOPIC_JOINT_STATES]
            if lw is not None and time.monotonic() - lw > self.p["stale_timeout_s"]:
                if not getattr(self, "_stale", False):
                    self._stale = True
                    self._close_mission_windows_only()
                self._publish_status(stale_js=True)
            else:
                self._stale = False

        def _close_mission_windows_only(self):
            self._flush_rows()
            self.core.flush()
            self._submit_windows(final=True)
            self._drain_windows(wait=True)

        def release(self):
            if self._rt is not None:
                self._rt_stop.set()
                self._rt.join(timeout=2.0)
                self._rt_exec.shutdown()
                self._rt_node.destroy_node()
                self._rt = None
            if self._pool is not None:
                self._pool.shutdown(wait=True)
                self._pool = None

    return bring_up(OnboardNode(), autostart)


def _parse_references(refs: Any, where: str) -> dict[str, dict[str, Any]]:
    """Twin-state ``references`` -> ``{actuator: {"stiffness": StiffnessReference, "friction": FrictionReference}}``
    (validated; ValueError naming the actuator and monitor). A state without the key gives {}."""
    from hd_onboard.detector import FrictionReference, StiffnessReference

    if not isinstance(refs, dict):
        raise ValueError(f"{where}: references must be a mapping actuator -> monitor -> values")
    out: dict[str, dict[str, Any]] = {}
    for act, mons in refs.items():
        if not isinstance(mons, dict):
            raise ValueError(f"{where}: references[{act}] must be a mapping")
        o: dict[str, Any] = {}
        if "stiffness" in mons:
            o["stiffness"] = StiffnessReference.from_dict(mons["stiffness"], f"{where} references[{act}][stiffness]")
        if "friction" in mons:
            o["friction"] = FrictionReference.from_dict(mons["friction"], f"{where} references[{act}][friction]")
        out[str(act)] = o
    return out


def _normal_priority() -> None:
    """Worker threads (window features) run SCHED_OTHER even in a process started real-time
    (``hdphm node onboard --rt-priority``): they must never delay the joint-state path."""
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        ru.set_thread_realtime(0)


class _Done:
    """A finished 'future' (no worker thread)."""

    def __init__(self, value):
        self.value = value

    def done(self) -> bool:
        return True

    def result(self):
        return self.value


def _float_or_nan(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _feature_fn(meta: dict, N: float):
    """Window features from ``hd_onboard.features.block_features`` (None when that module is unavailable)."""
    try:
        from hd_onboard.features import block_features
    except ImportError:
        return None
    k_t = float(meta.get("torque_constant") or 0.3)

    def fn(stamps_s, V, temperature):
        t = stamps_s - stamps_s[0]
        temp = np.full(len(t), temperature) if np.isfinite(temperature) else None
        f = block_features(t, V[:, 0], V[:, 1], V[:, 2], V[:, 3], V[:, 4], V[:, 5], N, k_t,
                           temp, None, None, "onboard window")
        return {k: v for k, v in f.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}

    return fn
