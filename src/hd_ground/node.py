"""Ground node (non-real-time module): archive in; recalibrated twin and adaptive thresholds out.

On start (``run_on_start``) and whenever a message arrives on
``/hd/ground/trigger`` (std_msgs/String, any content), it analyses the
mission archive ``archive_dir`` in a worker thread (the executor keeps
serving the other nodes): per actuator, the first ``healthy_missions``
missions (in ``mission_index`` order) are taken as healthy reference
(:func:`hd_ground.analysis.analyse_archive`: recalibrated parameters, per-channel residual lines
``thresholds`` and the stiffness/friction monitors' healthy laws ``references``). The result is
pushed as one JSON update on ``/hd/twin/update`` (``params``, ``thresholds``, ``references``; the
twin core validates it, bumps its revision and republishes the state the onboard node applies per
actuator) and a report on ``/hd/ground/report``. This module is the ROS shell only.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from std_msgs.msg import String
from std_srvs.srv import Trigger

import hd_ros as ru
from hd_ground.analysis import analyse_archive
from hd_ros.managed import ManagedNode, bring_up

NODE_NAME = "ground"
TOPIC_TRIGGER = "/hd/ground/trigger"
#: std_srvs/Trigger service: start a ground analysis, answered at once (started / busy / no archive)
SERVICE_ANALYSE = "/hd/ground/analyse"
PARAMS: dict[str, Any] = {
    "archive_dir": "",  # "" -> idle until configured
    "healthy_missions": 3,
    "run_on_start": True,
    "recalibrate": True,
    "model_dir": "",  # twin the onboard node runs (ONNX dir); "" -> physics stand-in: residuals must match it
    "store_dir": "",  # fleet store (hd_ground.fleet): "" -> none; else the archive's new missions are added to it
    "fleet_scheduler": "local:1",  # Dask scheduler of that fleet analysis (local[:N] or tcp://HOST:PORT)
}


class GroundNode(ManagedNode):
    def __init__(self, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True):
        super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)
        self.n_runs = 0

    def configure(self):
        self.pub_update = self.create_publisher(String, ru.TOPIC_TWIN_UPDATE, ru.qos("latched"))
        self.pub_report = self.create_publisher(String, ru.TOPIC_GROUND_REPORT, ru.qos("latched"))
        self.create_subscription(String, TOPIC_TRIGGER, lambda m: self.start(), ru.qos("stream"))
        self.create_service(Trigger, SERVICE_ANALYSE, self._on_analyse)
        self.result: tuple[dict, dict] | None = None
        self.error: str | None = None
        self.busy = False
        self._lock = threading.Lock()
        self.create_timer(0.2, self._deliver)
        ru.contain_callbacks(self, "hdphm/ground")  # no exception of a callback stops the node

    def activate(self):
        if self.p["run_on_start"] and self.p["archive_dir"]:
            self.start()

    def start(self) -> tuple[bool, str]:
        if not self.p["archive_dir"]:
            self.get_logger().warning("ground: no archive_dir parameter; nothing to analyse")
            return False, "no archive_dir parameter: nothing to analyse"
        with self._lock:
            if self.busy:
                return False, "an analysis is already running"
            self.busy = True
        threading.Thread(target=self._work, daemon=True).start()
        return True, f"analysis of {self.p['archive_dir']} started (results on {ru.TOPIC_GROUND_REPORT})"

    def _on_analyse(self, request, response):
        response.success, response.message = self.start()
        return response

    def _work(self):
        t0 = time.time()
        try:
            upd, rep = analyse_archive(self.p["archive_dir"], int(self.p["healthy_missions"]), bool(self.p["recalibrate"]),
                                       log=lambda s: self.get_logger().warning(s), model_dir=self.p["model_dir"])
            if self.p["store_dir"]:  # the same store `hdphm ground fleet` writes and `hdphm fleet` reads
                rep["fleet"] = self._fleet()
            rep["wall_s"] = time.time() - t0
            self.result = (upd, rep)
        except Exception as e:  # noqa: BLE001 - report, never crash the stack
            self.error = f"{type(e).__name__}: {e}"
            self.get_logger().error(f"ground analysis failed: {self.error}")
        finally:
            self.busy = False

    def _fleet(self) -> dict:
        from hd_ground.fleet.run import fleet_status, run_fleet
        from hd_ground.fleet.tasks import FleetOptions

        s = run_fleet([self.p["archive_dir"]], self.p["store_dir"], self.p["fleet_scheduler"],
                      FleetOptions(healthy_missions=int(self.p["healthy_missions"]), model_dir=self.p["model_dir"]),
                      progress=False, log=lambda s: self.get_logger().info(s))
        return {"summary": s, "status": fleet_status(self.p["store_dir"])}

    def _deliver(self):
        if self.result is None:
            return
        upd, rep = self.result
        self.result = None
        self.pub_update.publish(ru.json_msg(upd))
        self.pub_report.publish(ru.json_msg(rep))
        self.n_runs += 1
        self.get_logger().info(f"ground: pushed thresholds for {len(upd['thresholds'])} actuator(s), monitor references "
                               f"for {len(upd.get('references', {}))}"
                               + (" and recalibrated parameters" if "params" in upd else ""))


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True) -> GroundNode:
    """The ground node (managed; configured and activated unless ``autostart`` is False)."""
    return bring_up(GroundNode(context, overrides, param_services), autostart)
