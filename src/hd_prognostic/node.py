"""Prognostic node (partially real-time module): features in; health indicator and RUL out, at a lower rate.

Subscribes ``/hd/onboard/features`` (window rows: ``feat.HF_MTW_IF``,
``feat.W_load`` and residual statistics), ``/hd/mission`` (mission
boundaries). Per actuator it keeps one particle filter of the Archard wear
model (``hd_prognostic.hd.build_model`` on the observation model file,
parameter ``obs_model``; default ``hd_prognostic/default_obs_model.json``)
and makes **one filter step per mission**, as the batch prognosis does, with
the same reduction of the window rows (``hd_onboard.features.mission_observation``,
which batch applies to the same 1 s windows): the mission's observation is
the median of its window ``HF_MTW_IF`` values, its exposure the sum of the
window load-sliding integrals ``W_load`` [J].
During a mission, every ``publish_period_s`` of wall time, it publishes a
provisional estimate (a copy of the filter updated with the mission so far).

Mission boundaries: ``/hd/mission`` messages are queued; window rows carry
the onboard's ``mission_index`` and, on the last window of a mission,
``final`` = 1. A mission's filter step is committed on its final row (or when
a row of another mission arrives), so the last windows of a mission that
arrive after the next ``/hd/mission`` are still counted for the right one.

Publishes ``/hd/prognostic/health`` (Float64MultiArray row, columns
:data:`HEALTH_COLUMNS`: health indicator h [m] mean/P5/P95, RUL P5/P50/P95
in missions, risk of failure within ``risk_horizon`` missions, the
observation used) and ``/diagnostics`` ``hdphm/prognostic`` per actuator.
Without an observation model the node still publishes the observed
indicator and reports RUL as NaN with a WARN saying why.
"""

from __future__ import annotations

import copy
import math
from collections import deque
import time
from pathlib import Path
from typing import Any

import numpy as np

import hd_ros as ru

NODE_NAME = "prognostic"
HEALTH_COLUMNS = ("stamp", "mission_index", "final", "h_mean", "h_p5", "h_p95", "rul_p5", "rul_p50", "rul_p95",
                  "risk", "observation", "n_windows")
PARAMS: dict[str, Any] = {
    "obs_model": "",  # ObservationModel JSON; "" -> hd_prognostic/default_obs_model.json when present
    # life model from 'hdphm prognostic fit' (fleet failures/removals/inspections); when set it replaces
    # the observation-model particle filter: h_* columns are then the latent degradation (1 = median threshold)
    "life_model": "",
    "n_particles": 1000,
    "rul_particles": 500,
    "max_missions": 2000,
    "risk_horizon": 10.0,  # missions
    "publish_period_s": 1.0,
    "seed": 0,
}


class ActuatorTracker:
    """Per-actuator mission-step particle filter (pure; the node feeds it)."""

    def __init__(self, actuator: str, obs, p: dict[str, Any]):
        self.actuator = actuator
        self.obs = obs
        self.p = p
        self.model = None
        self.pf = None
        self.y_hist: list[float] = []
        self.W_hist: list[float] = []
        self.W_prev = 0.0
        self.mission_index = math.nan
        self.windows: list[dict] = []
        if obs is not None:
            from hd_prognostic.hd import build_model
            from hd_prognostic.pf import ParticleFilter

            self.model = build_model(obs)
            self.pf = ParticleFilter(self.model, n_particles=int(p["n_particles"]), seed=int(p["seed"]),
                                     likelihood="student_t", roughening=0.05)

    def add_windows(self, rows: list[dict]) -> None:
        self.windows.extend(rows)

    def _mission_obs(self) -> tuple[float, float]:
        """(HF_MTW_IF, W_load) of the mission so far: :func:`hd_onboard.features.mission_observation`."""
        from hd_onboard.features import mission_observation

        o = mission_observation(self.windows)
        return o["HF_MTW_IF"], o["W_load"]

    def estimate(self, final: bool) -> dict[str, float]:
        """Step (final: commit the mission) or provisional estimate (on a copy)."""
        y, W = self._mission_obs()
        out = {"mission_index": self.mission_index, "final": float(final), "observation": y,
               "n_windows": float(len(self.windows))}
        if self.pf is None:
            out.update(h_mean=math.nan, h_p5=math.nan, h_p95=math.nan, rul_p5=math.nan, rul_p50=math.nan,
                       rul_p95=math.nan, risk=math.nan)
            if final:
                self.windows = []
            return out
        pf = self.pf if final else copy.deepcopy(self.pf)
        ys = self.obs.normalise(np.array(self.y_hist + [y]))
        z = float(ys[-1])
        pf.predict(self.W_prev)
        pf.update(z if np.isfinite(z) else math.nan)
        from hd_prognostic.pf import weighted_quantile
        from hd_prognostic.rul import rul_distribution

        w = pf.weights
        h = pf.x[:, 0]
        q = weighted_quantile(h, w, [0.05, 0.5, 0.95])
        past = np.array([v for v in self.W_hist + [W] if np.isfinite(v) and v > 0])
        fut = past if len(past) >= 3 else float(self.obs.degradation.get("W_median", W if np.isfinite(W) else 1.0))
        k = min(int(self.p["rul_particles"]), pf.n)
        sel = np.random.default_rng(0).choice(pf.n, size=k, p=w / w.sum())
        r = rul_distribution(self.model, pf.x[sel], None, future=fut, step=1.0, max_steps=int(self.p["max_missions"]))
        out.update(h_mean=float(np.sum(w * h) / np.sum(w)), h_p5=float(q[0]), h_p95=float(q[2]),
                   rul_p5=r.p5, rul_p50=r.p50, rul_p95=r.p95, risk=float(r.risk(self.p["risk_horizon"])[0]))
        if final:
            self.y_hist.append(y)
            self.W_hist.append(W)
            self.W_prev = W if np.isfinite(W) else (float(np.median(past)) if len(past) else 0.0)
            self.windows = []
        return out


class LifeTracker:
    """Per-actuator prognosis with the fleet life model (:mod:`hd_prognostic.lifemodel`), one record per
    mission, the same per-mission observation as batch (``mission_observation`` of the window rows)."""

    def __init__(self, actuator: str, model, p: dict[str, Any]):
        self.actuator, self.model, self.p = actuator, model, p
        self.t: list[float] = []
        self.y: list[float] = []
        self.E: list[float] = []
        self.W_sum = 0.0
        self.mission_index = math.nan
        self.hours = math.nan
        self.windows: list[dict] = []
        self.rng = np.random.default_rng(int(p["seed"]))

    def add_windows(self, rows: list[dict]) -> None:
        self.windows.extend(rows)

    def _exposure(self, k: float) -> tuple[float, float]:
        """(exposure at the start of this mission, at the start of the next) for the model's clock."""
        from hd_onboard.features import mission_observation

        W = mission_observation(self.windows)["W_load"] if self.windows else math.nan
        ex = self.model.exposure
        if ex == "missions":
            return k, k + 1.0
        if ex == "hours":
            hpm = float(self.model.fit_info.get("hours_per_step") or 0.0)
            return self.hours, self.hours + hpm
        if not math.isfinite(W):
            W = self.W_sum / max(len(self.t), 1) if self.t else 0.0
        return self.W_sum, self.W_sum + W

    def estimate(self, final: bool) -> dict[str, float]:
        from hd_onboard.features import mission_observation
        from hd_prognostic.lifemodel import UnitHistory, predict_at

        o = mission_observation(self.windows)
        y = float(o.get(self.model.feature, math.nan))
        k = self.mission_index if math.isfinite(self.mission_index) else float(len(self.t))
        E0, E1 = self._exposure(k)
        out = {"mission_index": k, "final": float(final), "observation": y, "n_windows": float(len(self.windows))}
        t = self.t + [k]
        if len(t) > 1 and t[-1] <= t[-2]:  # repeated / unknown mission index: count missions instead
            t[-1] = t[-2] + 1.0
        u = UnitHistory(self.actuator, np.array(t), np.array(self.y + [y]), np.array(self.E + [E0]),
                        discrete=True, E_next=E1)
        if not math.isfinite(E0):
            out.update(h_mean=math.nan, h_p5=math.nan, h_p95=math.nan, rul_p5=math.nan, rul_p50=math.nan,
                       rul_p95=math.nan, risk=math.nan)
        else:
            r = predict_at(self.model, u, self.rng, int(self.p["rul_particles"]))
            q = np.quantile(r["rul"], [0.05, 0.5, 0.95])
            out.update(h_mean=r["latent"][1], h_p5=r["latent"][0], h_p95=r["latent"][2], rul_p5=float(q[0]),
                       rul_p50=float(q[1]), rul_p95=float(q[2]),
                       risk=float(np.mean(r["rul"] <= float(self.p["risk_horizon"]))))
        if final:
            self.t.append(float(t[-1]))
            self.y.append(y)
            self.E.append(E0)
            if self.model.exposure == "load":
                self.W_sum = E1
            self.windows = []
        return out


def load_life_model(path: str):
    from hd_prognostic.lifemodel import LifeModel

    try:
        return LifeModel.from_json(path), ""
    except (OSError, ValueError, KeyError) as e:
        return None, f"{path}: life model unusable ({e})"


def load_obs_model(path: str):
    from hd_prognostic.observation import ObservationModel

    if not path:
        cand = Path(__file__).with_name("default_obs_model.json")
        if not cand.is_file():
            return None, f"no observation model ({cand.name} absent; set parameter obs_model)"
        path = str(cand)
    try:
        return ObservationModel.from_json(path), ""
    except (OSError, ValueError, KeyError) as e:
        return None, f"{path}: observation model unusable ({e})"


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray, String

    from hd_ros.diagnostics import diag_status

    from hd_ros.managed import ManagedNode, bring_up

    class PrognosticNode(ManagedNode):
        def __init__(self):
            super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)

        def configure(self):
            self.life = None
            if self.p["life_model"]:
                self.life, self.obs_problem = load_life_model(self.p["life_model"])
                self.obs = None
            else:
                self.obs, self.obs_problem = load_obs_model(self.p["obs_model"])
            if self.obs_problem:
                self.get_logger().warning(self.obs_problem)
            self.trackers: dict[str, ActuatorTracker] = {}
            self.current: str | None = None
            self.pending: deque = deque()  # (actuator, mission_index) announced on /hd/mission, not yet current
            self.last: dict[str, dict] = {}
            self.history: dict[str, list[dict]] = {}  # final row of every mission, per actuator
            self.n_published = 0
            self.pub = self.create_publisher(Float64MultiArray, ru.TOPIC_HEALTH, ru.topic_qos(ru.TOPIC_HEALTH))
            self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
            self.create_subscription(Float64MultiArray, ru.TOPIC_FEATURES, self._on_features, ru.topic_qos(ru.TOPIC_FEATURES))
            self.create_subscription(String, ru.TOPIC_MISSION, self._on_mission, ru.mission_sub_qos())
            self.create_timer(float(self.p["publish_period_s"]), self._on_timer)
            self._dirty = False
            ru.contain_callbacks(self, "hdphm/prognostic")  # no exception of a callback stops the node

        def _tracker(self, act: str) -> ActuatorTracker:
            if act not in self.trackers:
                self.trackers[act] = (LifeTracker(act, self.life, self.p) if self.life is not None
                                      else ActuatorTracker(act, self.obs, self.p))
            return self.trackers[act]

        def _on_mission(self, msg):
            try:
                from hd_twin.state import check_mission

                meta = check_mission(ru.parse_json_msg(msg, ru.TOPIC_MISSION), ru.TOPIC_MISSION)
            except ValueError as e:
                self.get_logger().error(str(e))
                return
            try:
                mi = float(meta.get("mission_index", "nan"))
            except (TypeError, ValueError):
                mi = math.nan
            try:
                hrs = float(meta.get("operating_hours", "nan"))
            except (TypeError, ValueError):
                hrs = math.nan
            self.pending.append((str(meta.get("actuator_id", "unknown")), mi, hrs))
            if self.current is None:
                self._next_mission()

        def _next_mission(self):
            act, mi, hrs = self.pending.popleft()
            self.current = act
            self._tracker(act).mission_index = mi
            self._tracker(act).hours = hrs

        def _finalise(self):
            if self.current is not None:
                tr = self.trackers[self.current]
                if tr.windows:
                    self._publish(self.current, tr.estimate(final=True))
            self.current = None
            self._dirty = False

        def _on_features(self, msg):
            try:
                cols, rows = ru.unpack_table(msg)
            except ValueError as e:
                self.get_logger().error(f"{ru.TOPIC_FEATURES}: {e}")
                return
            for r in rows:
                w = dict(zip(cols, r.tolist()))
                mi = w.get("mission_index", math.nan)
                if self.current is not None and self.pending and math.isfinite(mi):
                    cur = self.trackers[self.current].mission_index
                    if mi != cur and any(m == mi for _, m, _h in self.pending):  # the onboard moved on
                        self._finalise()
                if self.current is None:
                    if self.pending:
                        self._next_mission()
                    else:
                        self.current = "unknown"
                        self._tracker("unknown")
                self.trackers[self.current].add_windows([w])
                self._dirty = True
                if w.get("final", 0.0) == 1.0:
                    self._finalise()

        def _on_timer(self):
            if self._dirty and self.current is not None and self.trackers[self.current].windows:
                self._dirty = False
                self._publish(self.current, self.trackers[self.current].estimate(final=False))

        def _publish(self, act: str, est: dict):
            est = dict(est, stamp=time.time())
            self.last[act] = est
            if est.get("final"):
                self.history.setdefault(act, []).append(est)
            self.pub.publish(ru.pack_table(HEALTH_COLUMNS, np.array([[float(est.get(c, math.nan)) for c in HEALTH_COLUMNS]])))
            self.n_published += 1
            lev = 1 if (self.obs is None and self.life is None) else (2 if est.get("risk", 0) > 0.5 else 1 if est.get("risk", 0) > 0.1 else 0)
            msg = self.obs_problem or f"RUL P50 {est['rul_p50']:.1f} missions (P5 {est['rul_p5']:.1f}, P95 {est['rul_p95']:.1f})"
            a = DiagnosticArray()
            a.header.stamp = self.get_clock().now().to_msg()
            a.status = [diag_status("hdphm/prognostic", lev, msg, act, est)]
            self.pub_diag.publish(a)

    return bring_up(PrognosticNode(), autostart)
