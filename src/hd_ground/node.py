"""Ground node (non-real-time module): archive in; recalibrated twin and adaptive thresholds out.

On start (``run_on_start``) and whenever a message arrives on
``/hd/ground/trigger`` (std_msgs/String, any content), it analyses the
mission archive ``archive_dir`` in a worker thread (the executor keeps
serving the other nodes): per actuator, the first ``healthy_missions``
missions (in ``mission_index`` order) are taken as healthy reference; the
onboard core runs on them in batch (same code as onboard), per-channel
thresholds come from their residuals (``hd_ground.thresholds``), and the
friction/inertia parameters are re-estimated by least squares
(``hd_ground.recalibration``). The result is pushed as one JSON update on
``/hd/twin/update`` (the twin core validates it, bumps its revision and
republishes the state the onboard node applies) and a report on
``/hd/ground/report``.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from hdphm import rosutil as ru

NODE_NAME = "ground"
TOPIC_TRIGGER = "/hd/ground/trigger"
PARAMS: dict[str, Any] = {
    "archive_dir": "",  # "" -> idle until configured
    "healthy_missions": 3,
    "run_on_start": True,
    "recalibrate": True,
}


def analyse_archive(archive_dir: str, healthy_missions: int = 3, do_recal: bool = True, log=print) -> tuple[dict, dict]:
    """(twin update, report) from a mission archive (pure: no ROS)."""
    from hd_ground.analytics import load_archive, mission_summary
    from hd_ground.recalibration import recalibrate
    from hd_ground.thresholds import actuator_thresholds
    from hd_onboard.core import run_mission
    from hd_twin import physics as ph

    if healthy_missions < 1 or healthy_missions > 10**5:
        raise ValueError(f"healthy_missions = {healthy_missions} must be in 1..1e5")
    arch = load_archive(archive_dir, log=log)
    if not arch:
        raise ValueError(f"{archive_dir}: no readable missions")
    params = ph.TwinParams.from_yaml()
    update: dict[str, Any] = {"thresholds": {}, "updated_by": "ground"}
    report: dict[str, Any] = {"archive_dir": str(archive_dir), "actuators": {}}
    healthy_all = []
    for act, missions in arch.items():
        ref = missions[:healthy_missions]
        healthy_all += ref
        res = [run_mission(m) for m in ref]
        th = actuator_thresholds(res)
        update["thresholds"][act] = {c: t.to_dict() for c, t in th.items()}
        report["actuators"][act] = {"missions": [int(m.meta.mission_index) for m in missions],
                                    "reference": [int(m.meta.mission_index) for m in ref],
                                    "reference_summary": [mission_summary(r) for r in res],
                                    "thresholds": update["thresholds"][act]}
    if do_recal:
        try:
            new, rep = recalibrate(healthy_all, params)
            update["params"] = {k: v for k, v in new.to_dict().items() if k not in ("mu_g", "K_out", "notes")}
            report["recalibration"] = rep
        except ValueError as e:
            report["recalibration"] = {"skipped": str(e)}
    return update, report


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True):
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from hd_onboard.node import declare

    class GroundNode(Node):
        def __init__(self):
            po = [Parameter(k, value=v) for k, v in (overrides or {}).items()]
            super().__init__(NODE_NAME, context=context, parameter_overrides=po,
                             start_parameter_services=param_services)
            self.p = declare(self, PARAMS)
            self.pub_update = self.create_publisher(String, ru.TOPIC_TWIN_UPDATE, ru.qos("latched"))
            self.pub_report = self.create_publisher(String, ru.TOPIC_GROUND_REPORT, ru.qos("latched"))
            self.create_subscription(String, TOPIC_TRIGGER, lambda m: self.start(), ru.qos("stream"))
            self.result: tuple[dict, dict] | None = None
            self.error: str | None = None
            self.busy = False
            self.n_runs = 0
            self._lock = threading.Lock()
            self.create_timer(0.2, self._deliver)
            if self.p["run_on_start"] and self.p["archive_dir"]:
                self.start()

        def start(self):
            if not self.p["archive_dir"]:
                self.get_logger().warning("ground: no archive_dir parameter; nothing to analyse")
                return
            with self._lock:
                if self.busy:
                    return
                self.busy = True
            threading.Thread(target=self._work, daemon=True).start()

        def _work(self):
            t0 = time.time()
            try:
                upd, rep = analyse_archive(self.p["archive_dir"], int(self.p["healthy_missions"]), bool(self.p["recalibrate"]),
                                           log=lambda s: self.get_logger().warning(s))
                rep["wall_s"] = time.time() - t0
                self.result = (upd, rep)
            except Exception as e:  # noqa: BLE001 - report, never crash the stack
                self.error = f"{type(e).__name__}: {e}"
                self.get_logger().error(f"ground analysis failed: {self.error}")
            finally:
                self.busy = False

        def _deliver(self):
            if self.result is None:
                return
            upd, rep = self.result
            self.result = None
            self.pub_update.publish(ru.json_msg(upd))
            self.pub_report.publish(ru.json_msg(rep))
            self.n_runs += 1
            self.get_logger().info(f"ground: pushed thresholds for {len(upd['thresholds'])} actuator(s)"
                                   + (" and recalibrated parameters" if "params" in upd else ""))

    return GroundNode()
