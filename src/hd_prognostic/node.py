"""Prognostic node (partially real-time module): features in; health indicator and RUL out, at a lower rate.

Subscribes ``/hd/onboard/features`` (window rows: ``feat.HF_MTW_IF``,
``feat.W_load`` and residual statistics), ``/hd/mission`` (mission
boundaries). Per actuator it keeps one particle filter of the Archard wear
model (:class:`hd_prognostic.tracker.ActuatorTracker`: ``hd_prognostic.pipeline.build_model`` on the observation model file,
parameter ``obs_model``; default ``hd_prognostic/default_obs_model.json``)
and makes **one filter step per mission**, as the batch prognosis does, with
the same reduction of the window rows (``hd_onboard.features.mission_observation``,
which batch applies to the same 1 s windows): the mission's observation is
the median of its window ``HF_MTW_IF`` values, its exposure the sum of the
window load-sliding integrals ``W_load`` [J].
During a mission, every ``publish_period_s`` of wall time, it publishes a
provisional estimate (a copy of the filter updated with the mission so far).

Mission boundaries (:class:`hd_prognostic.tracker.MissionRouter`): ``/hd/mission`` messages are
queued; window rows carry the onboard's ``mission_index`` and, on the last window of a mission,
``final`` = 1. A mission's filter step is committed on its final row (or when
a row of another mission arrives), so the last windows of a mission that
arrive after the next ``/hd/mission`` are still counted for the right one.
This module is the ROS shell only: callbacks convert messages and delegate to the router.

Publishes ``/hd/prognostic/health`` (Float64MultiArray row, columns
:data:`HEALTH_COLUMNS`: health indicator h [m] mean/P5/P95, RUL P5/P50/P95
in missions, risk of failure within ``risk_horizon`` missions, the
observation used) and ``/diagnostics`` ``hdphm/prognostic`` per actuator.
Without an observation model the node still publishes the observed
indicator and reports RUL as NaN with a WARN saying why.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Float64MultiArray, String

import hd_ros as ru
from hd_prognostic.tracker import (TRACKER_DEFAULTS, ActuatorTracker, LifeTracker, MissionRouter,  # noqa: F401
                                   load_life_model, load_obs_model)
from hd_ros.managed import ManagedNode, bring_up

NODE_NAME = "prognostic"
HEALTH_COLUMNS = ("stamp", "mission_index", "final", "h_mean", "h_p5", "h_p95", "rul_p5", "rul_p50", "rul_p95",
                  "risk", "observation", "n_windows")
PARAMS: dict[str, Any] = {
    "obs_model": "",  # ObservationModel JSON; "" -> hd_prognostic/default_obs_model.json when present
    # life model from 'hdphm prognostic fit' (fleet failures/removals/inspections); when set it replaces
    # the observation-model particle filter: h_* columns are then the latent degradation (1 = median threshold)
    "life_model": "",
    **TRACKER_DEFAULTS,  # n_particles, rul_particles, max_missions, risk_horizon (missions), seed
    "publish_period_s": 1.0,
}


class PrognosticNode(ManagedNode):
    def __init__(self, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True):
        super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)

    def configure(self):
        self.life = self.obs = None
        if self.p["life_model"]:
            self.life, self.obs_problem = load_life_model(self.p["life_model"])
        else:
            self.obs, self.obs_problem = load_obs_model(self.p["obs_model"])
        if self.obs_problem:
            self.get_logger().warning(self.obs_problem)
        self.router = MissionRouter(lambda act: LifeTracker(act, self.life, self.p) if self.life is not None
                                    else ActuatorTracker(act, self.obs, self.p))
        self.last: dict[str, dict] = {}
        self.history: dict[str, list[dict]] = {}  # final row of every mission, per actuator
        self.n_published = 0
        self.pub = self.create_publisher(Float64MultiArray, ru.TOPIC_HEALTH, ru.topic_qos(ru.TOPIC_HEALTH))
        self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
        self.create_subscription(Float64MultiArray, ru.TOPIC_FEATURES, self._on_features, ru.topic_qos(ru.TOPIC_FEATURES))
        self.create_subscription(String, ru.TOPIC_MISSION, self._on_mission, ru.mission_sub_qos())
        self.create_timer(float(self.p["publish_period_s"]), self._on_timer)
        ru.contain_callbacks(self, "hdphm/prognostic")  # no exception of a callback stops the node

    @property
    def trackers(self) -> dict:
        return self.router.trackers

    def _on_mission(self, msg):
        from hd_twin.state import check_mission

        try:
            self.router.announce(check_mission(ru.parse_json_msg(msg, ru.TOPIC_MISSION), ru.TOPIC_MISSION))
        except ValueError as e:
            self.get_logger().error(str(e))

    def _on_features(self, msg):
        try:
            cols, rows = ru.unpack_table(msg)
        except ValueError as e:
            self.get_logger().error(f"{ru.TOPIC_FEATURES}: {e}")
            return
        for act, est in self.router.rows([dict(zip(cols, r.tolist())) for r in rows]):
            self._publish(act, est)

    def _on_timer(self):
        got = self.router.provisional()
        if got is not None:
            self._publish(*got)

    def _publish(self, act: str, est: dict):
        est = dict(est, stamp=time.time())
        self.last[act] = est
        if est.get("final"):
            self.history.setdefault(act, []).append(est)
        self.pub.publish(ru.pack_table(HEALTH_COLUMNS, np.array([[float(est.get(c, math.nan)) for c in HEALTH_COLUMNS]])))
        self.n_published += 1
        risk = est.get("risk", 0)
        lev = 1 if (self.obs is None and self.life is None) else (2 if risk > 0.5 else 1 if risk > 0.1 else 0)
        msg = self.obs_problem or f"RUL P50 {est['rul_p50']:.1f} missions (P5 {est['rul_p5']:.1f}, P95 {est['rul_p95']:.1f})"
        self.pub_diag.publish(ru.diag_array(self, [ru.diag_status("hdphm/prognostic", lev, msg, act, est)]))


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True) -> PrognosticNode:
    """The prognostic node (managed; configured and activated unless ``autostart`` is False)."""
    return bring_up(PrognosticNode(context, overrides, param_services), autostart)
