"""Onboard node (real-time module): contract topics in; residuals, flags, features out.

A thin rclpy shell over :class:`hd_onboard.core.OnboardCore`: callbacks decode (``hd_ros``),
delegate to the core and publish what it produced. Subscriptions take raw CDR and drain their
whole queue per callback, so the core sees blocks (``hd_ros.convert.take_all``). The twin state is
read by :func:`hd_twin.state.read_state`, window features are computed off the flag path by
:class:`hd_onboard.windowpool.WindowFeaturePool`, the diagnostics' content comes from
:mod:`hd_onboard.status`.

Subscribes: ``/hd/joint_states``, ``/hd/command``, ``/hd/temperature``
(sensor QoS), ``/hd/mission`` (JSON ``hd_mission`` metadata, latched: a new
mission resets the core; hardware_id = its actuator_id), ``/hd/twin/state``
(latched JSON: twin parameters, model version, per-actuator thresholds and
stiffness/friction monitor references: a ground reference for this node's
actuator wins over the warm-up's, status ``reference`` = "ground").
Publishes: ``/hd/onboard/residuals`` (Float64MultiArray rows, columns
``hd_onboard.residuals.RESIDUAL_COLUMNS``, one message per processed block),
``/hd/onboard/features`` (one row per closed window: residual statistics and
features), ``/diagnostics`` (stable names ``hdphm/onboard/...``, see
``docs/INTERFACES.md``) on every level change and every
``diag_period_s`` of sample time, and STALE when joint states stop for
``stale_timeout_s`` of wall time (temperature / command are STALE when
joint-state time advanced ``stale_timeout_s`` past their last sample).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64MultiArray, String

import hd_ros as ru
from hd_onboard.config import OnboardConfig
from hd_onboard.detectors.levels import LEVEL_NAMES, OK
from hd_onboard.residuals import CHANNELS, RESIDUAL_COLUMNS
from hd_onboard.session import OnboardSession
from hd_onboard.status import onboard_statuses
from hd_onboard.windowpool import WindowFeaturePool
from hd_ros.managed import ManagedNode, bring_up
from hd_twin import state as sv

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


#: every OnboardConfig field is a node parameter with the core's default (one source for detection
#: settings: the node never carries its own copy of them)
PARAMS.update({f.name: f.default for f in dataclasses.fields(OnboardConfig)})


class OnboardNode(ManagedNode):
    def __init__(self, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True):
        super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)
        self._rt = None
        self._pool = None

    def configure(self):
        cfg = OnboardConfig(**{k: self.p[k] for k in OnboardConfig.__dataclass_fields__ if k in self.p}).validate()
        #: this actuator's monitoring: core, twin, lines, references, mission metadata (hd_onboard.session)
        self.session = OnboardSession(cfg, self.p["model_dir"], self.p["gear_ratio"], self.p["actuator_id"] or "",
                                      log=lambda s: self.get_logger().warning(s))
        self.n_msgs = {t: 0 for t in ru.CONTRACT_TOPICS}  # decoded messages
        self.n_taken = {t: 0 for t in ru.CONTRACT_TOPICS}  # messages taken from DDS (decodable or not)
        self.n_mission_msgs = 0  # /hd/mission messages taken
        self.n_bad = 0
        self.last_wall = {t: None for t in ru.CONTRACT_TOPICS}
        self.last_stamp = {t: None for t in ru.CONTRACT_TOPICS}
        self.last_diag_t = -math.inf
        self.level = OK
        self._stale = False
        self.latency_s: list[float] = []  # arrival -> flag decision, per block (bench)
        self.n_published = {ru.TOPIC_RESIDUALS: 0, ru.TOPIC_FEATURES: 0, ru.TOPIC_DIAGNOSTICS: 0}
        self.errors: list[str] = []
        self.input_problems: list[tuple[str, int, str]] = []  # (key, level, message): OnboardCore input notes
        self.latency_ns: list[int] = []  # latency_probe: per sample, decision wall time - header.stamp
        self.flags: list[tuple[str, int, int, str]] = []  # (actuator, stamp_ns, level, reason)
        self._pool = WindowFeaturePool(threaded=bool(self.p["feature_thread"]))
        self.pub_res = self.create_publisher(Float64MultiArray, ru.TOPIC_RESIDUALS, ru.topic_qos(ru.TOPIC_RESIDUALS))
        self.pub_feat = self.create_publisher(Float64MultiArray, ru.TOPIC_FEATURES, ru.topic_qos(ru.TOPIC_FEATURES))
        self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
        self._lock = threading.RLock()  # the core is shared by the joint-state thread and the others
        if self.p["rt_thread"]:
            # joint states alone in a wait set (a few entities instead of all the node's): the executor's
            # per-wake cost, not the core, dominates the arrival -> flag latency at 1 kHz
            self._rt_node = Node(NODE_NAME + "_rt", context=self.context, start_parameter_services=False)
            self.sub_js = self._rt_node.create_subscription(JointState, ru.TOPIC_JOINT_STATES, self._on_js_rt,
                                                            ru.qos("sensor"), raw=True)
            self._rt_exec = ru.make_executor(self.context)
            self._rt_exec.add_node(self._rt_node)
            self._rt_stop = threading.Event()
            self._rt = threading.Thread(target=self._rt_spin, name="onboard-joint-states", daemon=True)
        else:
            self.sub_js = self.create_subscription(JointState, ru.TOPIC_JOINT_STATES, self._on_js, ru.qos("sensor"), raw=True)
        self.sub_cmd = self.create_subscription(JointState, ru.TOPIC_COMMAND, self._locked(self._on_cmd), ru.qos("sensor"), raw=True)
        self.sub_tmp = self.create_subscription(Temperature, ru.TOPIC_TEMPERATURE, self._locked(self._on_temp), ru.qos("sensor"), raw=True)
        self.sub_mission = self.create_subscription(String, ru.TOPIC_MISSION, self._on_mission_msg, ru.mission_sub_qos())
        self._t_start = time.monotonic()
        self.create_subscription(String, ru.TOPIC_TWIN_STATE, self._locked(self._on_twin), ru.qos("latched"))
        self.create_timer(max(0.1, self.p["stale_timeout_s"] / 4), self._locked(self._on_timer))
        self._new_core()
        self.get_logger().info(f"onboard up: twin={self.core.expected.kind} {self.core.expected.version}")
        ru.contain_callbacks(self, "hdphm/onboard")  # no exception of a callback stops the node
        if self._rt is not None:
            ru.contain_callbacks(self._rt_node, "hdphm/onboard")
            self._rt.start()

    def _locked(self, fn):
        def run(*a):
            with self._lock:
                return fn(*a)

        return run

    # ---- the joint-state thread (rt_thread) -------------------------------------------------------
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

    def _on_js_rt(self, first):
        if not self.is_active:  # the joint-state thread's own node is not gated by the lifecycle
            return
        with self._lock:
            self._on_js(first)

    # ---- the session's state, as attributes (tests, the stack's summary) ---------------------------
    core = property(lambda self: self.session.core)
    meta = property(lambda self: self.session.meta)
    hardware_id = property(lambda self: self.session.hardware_id)
    thresholds_all = property(lambda self: self.session.thresholds_all)
    references_all = property(lambda self: self.session.references_all)
    twin_params = property(lambda self: self.session.twin_params)
    twin_state = property(lambda self: self.session.twin_state)

    # ---- core and mission -------------------------------------------------------------------------
    def _new_core(self, why: str | None = None):
        """After the session started a core (``why``: its twin fell back): report, reset the published level."""
        why = self.session.new_core() if why is None else why
        if why:
            self.input_problems.append(("twin_load", 2, why))
            self._error(why)
        self.last_diag_t = -math.inf
        self.level = OK

    def _on_mission_msg(self, msg):
        self.n_mission_msgs += 1
        with self._lock:
            try:
                meta = sv.check_mission(ru.parse_json_msg(msg, ru.TOPIC_MISSION), ru.TOPIC_MISSION)
            except (ValueError, TypeError) as e:
                self._error(f"{ru.TOPIC_MISSION}: {e}")
                return
            self.close_mission()
            self._new_core(self.session.start_mission(meta))
            self.get_logger().debug(f"mission {meta.get('mission_index')} of {self.hardware_id}: core reset")

    def _poll_mission(self):
        sub = self.sub_mission
        with sub.handle:
            r = sub.handle.take_message(sub.msg_type, sub.raw)
        if r is not None:
            self._on_mission_msg(r[0])

    def close_mission(self):
        """End of the current mission: its last window and every pending row are published (in order).
        Called on every ``/hd/mission`` and, publicly, at the end of a replay."""
        if self.core is not None:
            self.core.end_mission()
            self._report_input()
            self._close_windows()

    def _close_windows(self):
        self._flush_rows()
        self.core.flush()
        self._submit_windows(final=True)
        self._publish_windows(wait=True)

    def _on_twin(self, msg):
        try:
            roots = sv.model_roots(self.p.get("model_roots", ""), self.p["model_dir"])
            st, params, ths, refs = sv.read_state(msg.data, ru.TOPIC_TWIN_STATE, roots, self.session.twin_params, CHANNELS)
        except ValueError as e:
            self._error(f"twin update refused: {e}")
            return
        why = self.session.apply_state(st, params, ths, refs)
        if why is not None:  # a new twin model: a new core
            self._new_core(why)
        self.get_logger().info(f"twin state revision {st.get('revision')} applied")

    # ---- inputs -----------------------------------------------------------------------------------
    def _on_js(self, first):
        t_arrival = time.perf_counter()
        msgs = ru.take_all(self.sub_js, first)
        self.n_taken[ru.TOPIC_JOINT_STATES] += len(msgs)
        short = int(self.p["short_path_max"])
        stamps, V, frame, problems = ru.decode_joint_states(msgs, vectorise_min=short + 1)
        for e in problems:
            self.n_bad += 1
            if self.n_bad <= 3:
                self._error(f"{ru.TOPIC_JOINT_STATES}: {e}")
        if not self.meta:  # a (re)started node: the latched mission may be queued behind the samples
            self._poll_mission()
        if not self.hardware_id and frame:
            self.session.hardware_id = frame
        n_ok = len(stamps)
        self.n_msgs[ru.TOPIC_JOINT_STATES] += n_ok
        self.last_wall[ru.TOPIC_JOINT_STATES] = time.monotonic()
        self.session.push_samples(stamps, V, short, int(self.p["max_block"]), lambda: self.level,
                                  lambda: self._after_samples(force_rows=True),
                                  self.latency_ns if self.p["latency_probe"] else None)
        core = self.core
        if n_ok:
            self.last_stamp[ru.TOPIC_JOINT_STATES] = int(core.last_ns) if core.last_ns is not None else None
        self._after_samples()
        self.latency_s.append(time.perf_counter() - t_arrival)

    def _on_cmd(self, first):
        msgs = ru.take_all(self.sub_cmd, first)
        self.n_taken[ru.TOPIC_COMMAND] += len(msgs)
        stamps, V, _, problems = ru.decode_joint_states(msgs)  # column 0: position[0] = theta_ref
        for e in problems:
            self._error(f"{ru.TOPIC_COMMAND}: {e}")
        self.n_msgs[ru.TOPIC_COMMAND] += len(stamps)
        if len(stamps):
            self.last_stamp[ru.TOPIC_COMMAND] = int(stamps[-1])
        self.session.push_commands(stamps, V)
        self.last_wall[ru.TOPIC_COMMAND] = time.monotonic()

    def _on_temp(self, first):
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
            self.session.push_temperature(s, frame, v)
        self.last_wall[ru.TOPIC_TEMPERATURE] = time.monotonic()

    # ---- outputs ----------------------------------------------------------------------------------
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
        if len(self._pool):
            self._publish_windows()

    def _flush_rows(self):
        tab = self.core.take_rows()
        if len(tab):
            self.pub_res.publish(ru.pack_table(RESIDUAL_COLUMNS, tab))
            self.n_published[ru.TOPIC_RESIDUALS] += 1

    def _submit_windows(self, final: bool = False):
        """The core's closed windows to the feature pool (``final``: the last one ends the mission)."""
        self._pool.submit(self.core.take_window_jobs(), self.core.feature_fn, self.meta.get("mission_index"), final)

    def _publish_windows(self, wait: bool = False):
        """Finished window rows (in window order) to ``/hd/onboard/features``."""
        rows = self._pool.drain(wait, lambda e: self.get_logger().error(f"window features failed: {type(e).__name__}: {e}"))
        if rows:
            keys = sorted({k for w in rows for k in w})
            self.pub_feat.publish(ru.pack_table(keys, np.array([[float(w.get(k, math.nan)) for k in keys] for w in rows])))
            self.n_published[ru.TOPIC_FEATURES] += 1

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
                self._publish_diag([("hdphm/onboard/input", lev, text[:200], self.hardware_id or "unknown", {"problem": key})])

    def _error(self, text: str):
        self.errors.append(text)
        self.get_logger().error(text)
        self._publish_diag([("hdphm/onboard/input", 2, text[:200], self.hardware_id or "unknown", {})])

    def _publish_status(self, stale_js: bool = False):
        if not self.hardware_id and time.monotonic() - self._t_start < self.p["stale_timeout_s"]:
            return  # neither /hd/mission nor a frame_id named the actuator yet: no status under "unknown"
        self._publish_diag(onboard_statuses(self.core, self.meta, self.hardware_id, self.n_msgs, self.last_stamp,
                                            self.n_bad, stale_js, self.p["stale_timeout_s"]))

    def _publish_diag(self, statuses):
        self.pub_diag.publish(ru.diag_array(self, [ru.diag_status(*s) for s in statuses]))
        self.n_published[ru.TOPIC_DIAGNOSTICS] += 1

    def _on_timer(self):
        if self.core is not None and len(self.core.rows):
            self._flush_rows()
        if len(self._pool):
            self._publish_windows()
        lw = self.last_wall[ru.TOPIC_JOINT_STATES]
        if lw is not None and time.monotonic() - lw > self.p["stale_timeout_s"]:
            if not self._stale:
                self._stale = True
                self._close_windows()
            self._publish_status(stale_js=True)
        else:
            self._stale = False

    def release(self):
        if self._rt is not None:
            self._rt_stop.set()
            self._rt.join(timeout=2.0)
            self._rt_exec.shutdown()
            self._rt_node.destroy_node()
            self._rt = None
        if self._pool is not None:
            self._pool.close()
            self._pool = None


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True) -> OnboardNode:
    """The onboard node (managed; configured and activated unless ``autostart`` is False)."""
    return bring_up(OnboardNode(context, overrides, param_services), autostart)
