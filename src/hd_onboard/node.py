"""Onboard node (real-time module): contract topics in; residuals, flags, features out.

A thin rclpy shell over :class:`hd_onboard.core.OnboardCore`: callbacks decode (``hd_ros``),
delegate to the core and publish what it produced. Subscriptions take raw CDR and drain their
whole queue per callback, so the core sees blocks (``hd_ros.convert.take_all``). The twin state is
read by :func:`hd_twin.state.read_state`, window features are computed off the flag path by
:class:`hd_onboard.windowpool.WindowFeaturePool`, the diagnostics' content comes from
:mod:`hd_onboard.status`, when rows / features / diagnostics go out (and the STALE watchdog) from
:class:`hd_onboard.publishing.PublishSchedule`; ``rt_thread`` puts joint states on their own thread
(:class:`hd_ros.rtthread.RtSubscription`).

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
import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Float64MultiArray, String

import hd_ros as ru
from hd_onboard.config import OnboardConfig
from hd_onboard.detectors.levels import LEVEL_NAMES
from hd_onboard.publishing import InputBook, PublishSchedule, window_table
from hd_onboard.residuals import CHANNELS, RESIDUAL_COLUMNS
from hd_onboard.session import OnboardSession
from hd_onboard.status import onboard_statuses
from hd_onboard.windowpool import WindowFeaturePool
from hd_ros.managed import ManagedNode, bring_up
from hd_ros.rtthread import RtSubscription
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
        p = self.p
        cfg = OnboardConfig(**{k: p[k] for k in OnboardConfig.__dataclass_fields__ if k in p}).validate()
        #: this actuator's monitoring: core, twin, lines, references, mission metadata (hd_onboard.session)
        self.session = OnboardSession(cfg, p["model_dir"], p["gear_ratio"], p["actuator_id"] or "",
                                      log=lambda s: self.get_logger().warning(s))
        #: when to publish what (hd_onboard.publishing); input counts of the reports
        self.schedule = PublishSchedule(p["diag_period_s"], p["residual_rows"], p["stale_timeout_s"], time.monotonic())
        self.book = InputBook(ru.CONTRACT_TOPICS)
        self.n_msgs, self.n_taken, self.last_wall, self.last_stamp = (
            self.book.n_msgs, self.book.n_taken, self.book.last_wall, self.book.last_stamp)
        self.n_mission_msgs = 0  # /hd/mission messages taken
        self.latency_s: list[float] = []  # arrival -> flag decision, per block (bench)
        self.n_published = {ru.TOPIC_RESIDUALS: 0, ru.TOPIC_FEATURES: 0, ru.TOPIC_DIAGNOSTICS: 0}
        self.errors: list[str] = []
        self.input_problems: list[tuple[str, int, str]] = []  # (key, level, message): OnboardCore input notes
        self.latency_ns: list[int] = []  # latency_probe: per sample, decision wall time - header.stamp
        self.flags: list[tuple[str, int, int, str]] = []  # (actuator, stamp_ns, level, reason)
        self._pool = WindowFeaturePool(threaded=bool(p["feature_thread"]))
        self.pub_res = self.create_publisher(Float64MultiArray, ru.TOPIC_RESIDUALS, ru.topic_qos(ru.TOPIC_RESIDUALS))
        self.pub_feat = self.create_publisher(Float64MultiArray, ru.TOPIC_FEATURES, ru.topic_qos(ru.TOPIC_FEATURES))
        self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
        self._lock = threading.RLock()  # the core is shared by the joint-state thread and the others
        if p["rt_thread"]:  # joint states alone in a wait set, on their own thread (hd_ros.rtthread)
            self._rt = RtSubscription(self.context, NODE_NAME + "_rt", JointState, ru.TOPIC_JOINT_STATES, self._on_js,
                                      ru.qos("sensor"), priority=int(p["rt_priority"]), gate=lambda: self.is_active,
                                      lock=self._lock, raw=True, thread_name="onboard-joint-states", label="joint-state",
                                      log=lambda lev, text: getattr(self.get_logger(), lev)(text))
            self.sub_js = self._rt.sub
        else:
            self.sub_js = self.create_subscription(JointState, ru.TOPIC_JOINT_STATES, self._on_js, ru.qos("sensor"), raw=True)
        self.sub_cmd = self.create_subscription(JointState, ru.TOPIC_COMMAND, self._locked(self._on_cmd), ru.qos("sensor"), raw=True)
        self.sub_tmp = self.create_subscription(Temperature, ru.TOPIC_TEMPERATURE, self._locked(self._on_temp), ru.qos("sensor"), raw=True)
        self.sub_mission = self.create_subscription(String, ru.TOPIC_MISSION, self._on_mission_msg, ru.mission_sub_qos())
        self.create_subscription(String, ru.TOPIC_TWIN_STATE, self._locked(self._on_twin), ru.qos("latched"))
        self.create_timer(max(0.1, p["stale_timeout_s"] / 4), self._locked(self._on_timer))
        self._new_core()
        self.get_logger().info(f"onboard up: twin={self.core.expected.kind} {self.core.expected.version}")
        ru.contain_callbacks(self, "hdphm/onboard")  # no exception of a callback stops the node
        if self._rt is not None:
            self._rt.contain("hdphm/onboard")
            self._rt.start()

    def _locked(self, fn):
        def run(*a):
            with self._lock:
                return fn(*a)

        return run

    # ---- the session's state, as attributes (tests, the stack's summary) ---------------------------
    core = property(lambda self: self.session.core)
    meta = property(lambda self: self.session.meta)
    hardware_id = property(lambda self: self.session.hardware_id)
    thresholds_all = property(lambda self: self.session.thresholds_all)
    references_all = property(lambda self: self.session.references_all)
    twin_params = property(lambda self: self.session.twin_params)
    twin_state = property(lambda self: self.session.twin_state)
    level = property(lambda self: self.schedule.level)  # the level last published

    # ---- core, mission, twin state ------------------------------------------------------------------
    def _new_core(self, why: str | None = None):
        """After the session started a core (``why``: its twin fell back): report, reset the published level."""
        why = self.session.new_core() if why is None else why
        if why:
            self.input_problems.append(("twin_load", 2, why))
            self._error(why)
        self.schedule.reset()

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
        with self.sub_mission.handle:
            r = self.sub_mission.handle.take_message(self.sub_mission.msg_type, self.sub_mission.raw)
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
        self._pool.submit(self.core.take_window_jobs(), self.core.feature_fn, self.meta.get("mission_index"), True)
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

    # ---- inputs: decode (hd_ros), count (InputBook), push (OnboardSession) ----------------------------
    def _on_js(self, first):
        t_arrival = time.perf_counter()
        msgs = ru.take_all(self.sub_js, first)
        book, short = self.book, int(self.p["short_path_max"])
        book.n_taken[ru.TOPIC_JOINT_STATES] += len(msgs)
        stamps, V, frame, problems = ru.decode_joint_states(msgs, vectorise_min=short + 1)
        for e in problems:
            if book.bad():
                self._error(f"{ru.TOPIC_JOINT_STATES}: {e}")
        if not self.meta:  # a (re)started node: the latched mission may be queued behind the samples
            self._poll_mission()
        if not self.hardware_id and frame:
            self.session.hardware_id = frame
        book.n_msgs[ru.TOPIC_JOINT_STATES] += len(stamps)
        book.last_wall[ru.TOPIC_JOINT_STATES] = time.monotonic()
        self.session.push_samples(stamps, V, short, int(self.p["max_block"]), lambda: self.schedule.level,
                                  lambda: self._after_samples(force_rows=True),
                                  self.latency_ns if self.p["latency_probe"] else None)
        if len(stamps):
            book.last_stamp[ru.TOPIC_JOINT_STATES] = int(self.core.last_ns) if self.core.last_ns is not None else None
        self._after_samples()
        self.latency_s.append(time.perf_counter() - t_arrival)

    def _on_cmd(self, first):
        msgs = ru.take_all(self.sub_cmd, first)
        self.book.n_taken[ru.TOPIC_COMMAND] += len(msgs)
        stamps, V, _, problems = ru.decode_joint_states(msgs)  # column 0: position[0] = theta_ref
        for e in problems:
            self._error(f"{ru.TOPIC_COMMAND}: {e}")
        self.book.n_msgs[ru.TOPIC_COMMAND] += len(stamps)
        if len(stamps):
            self.book.last_stamp[ru.TOPIC_COMMAND] = int(stamps[-1])
        self.session.push_commands(stamps, V)
        self.book.last_wall[ru.TOPIC_COMMAND] = time.monotonic()

    def _on_temp(self, first):
        msgs = ru.take_all(self.sub_tmp, first)
        self.book.n_taken[ru.TOPIC_TEMPERATURE] += len(msgs)
        for b in msgs:
            try:
                s, frame, v = ru.decode_temperature(b)
            except ru.CdrError as e:
                self._error(f"{ru.TOPIC_TEMPERATURE}: {e}")
                continue
            self.book.n_msgs[ru.TOPIC_TEMPERATURE] += 1
            self.book.last_stamp[ru.TOPIC_TEMPERATURE] = s
            self.session.push_temperature(s, frame, v)
        self.book.last_wall[ru.TOPIC_TEMPERATURE] = time.monotonic()

    # ---- outputs: what and when decided by PublishSchedule ------------------------------------------
    def _after_samples(self, force_rows: bool = False):
        """Publish what the core produced: flags first, then rows, diagnostics, windows."""
        core = self.core
        self._report_input()
        for s, lev, why in core.take_events():
            self.flags.append((self.hardware_id, s, lev, why))
            self.get_logger().warning(f"{self.hardware_id}: {LEVEL_NAMES[lev]} at stamp {s * 1e-9:.3f} s ({why})")
        report, rows = self.schedule.after_samples(core.level, core.last_ns, len(core.rows), force_rows)
        if report:
            self._publish_status()
        if rows:
            self._flush_rows()
        if core.window_jobs:
            self._pool.submit(core.take_window_jobs(), core.feature_fn, self.meta.get("mission_index"), False)
        if len(self._pool):
            self._publish_windows()

    def _flush_rows(self):
        tab = self.core.take_rows()
        if len(tab):
            self.pub_res.publish(ru.pack_table(RESIDUAL_COLUMNS, tab))
            self.n_published[ru.TOPIC_RESIDUALS] += 1

    def _publish_windows(self, wait: bool = False):
        """Finished window rows (in window order) to ``/hd/onboard/features``."""
        rows = self._pool.drain(wait, lambda e: self.get_logger().error(f"window features failed: {type(e).__name__}: {e}"))
        if rows:
            self.pub_feat.publish(ru.pack_table(*window_table(rows)))
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
        if self.schedule.may_report(self.hardware_id, time.monotonic()):
            self._publish_diag(onboard_statuses(self.core, self.meta, self.hardware_id, self.book.n_msgs, self.book.last_stamp,
                                                self.book.n_bad, stale_js, self.p["stale_timeout_s"]))

    def _publish_diag(self, statuses):
        self.pub_diag.publish(ru.diag_array(self, [ru.diag_status(*s) for s in statuses]))
        self.n_published[ru.TOPIC_DIAGNOSTICS] += 1

    def _on_timer(self):
        if self.core is not None and len(self.core.rows):
            self._flush_rows()
        if len(self._pool):
            self._publish_windows()
        close, stale = self.schedule.watchdog(self.book.last_wall[ru.TOPIC_JOINT_STATES], time.monotonic())
        if close:
            self._close_windows()
        if stale:
            self._publish_status(stale_js=True)

    def release(self):
        if self._rt is not None:
            self._rt.stop()
            self._rt = None
        if self._pool is not None:
            self._pool.close()
            self._pool = None


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True) -> OnboardNode:
    """The onboard node (managed; configured and activated unless ``autostart`` is False)."""
    return bring_up(OnboardNode(context, overrides, param_services), autostart)
