"""Per-actuator prognosis fed window rows, one filter step per mission (pure: no ROS).

Shared by the prognostic node (:mod:`hd_prognostic.node`, which only converts messages) and the tests
that hold it equal to batch: :class:`ActuatorTracker` (particle filter of the Archard wear model on an
observation model, the batch filter's settings :func:`hd_prognostic.pipeline.pf_settings`),
:class:`LifeTracker` (the fleet life model, :mod:`hd_prognostic.lifemodel`), and :class:`MissionRouter`
(mission boundaries: ``/hd/mission`` announcements and the onboard's ``mission_index`` / ``final``
window columns decide which mission a row belongs to and when a mission's step is committed).
The per-mission observation is :func:`hd_onboard.features.mission_observation` of the window rows, as
batch reduces the same 1 s windows.
"""

from __future__ import annotations

import copy
import math
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

#: tracker settings (the node declares them as parameters)
TRACKER_DEFAULTS: dict[str, Any] = {
    "n_particles": 1000,
    "rul_particles": 500,
    "max_missions": 2000,
    "risk_horizon": 10.0,  # missions
    "seed": 0,
}

class ActuatorTracker:
    """Per-actuator mission-step particle filter of the observation model (pure; the node feeds it window rows)."""

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
            from hd_prognostic.pipeline import build_model, pf_settings
            from hd_prognostic.pf import ParticleFilter

            self.model = build_model(obs)
            # the batch filter's settings (hd_prognostic.pipeline.pf_settings), one step per mission as batch
            self.pf = ParticleFilter(self.model, **pf_settings(obs), n_particles=int(p["n_particles"]), seed=int(p["seed"]))

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




class MissionRouter:
    """Which actuator and mission the incoming window rows belong to, and when a mission is committed.

    ``/hd/mission`` announcements are queued (:meth:`announce`); window rows carry the onboard's
    ``mission_index`` and, on the last window of a mission, ``final`` = 1. A mission's filter step is
    committed on its final row (or when a row of another announced mission arrives), so the last
    windows of a mission that arrive after the next ``/hd/mission`` are still counted for the right
    one. ``make_tracker(actuator)`` builds a tracker on first use.
    """

    def __init__(self, make_tracker):
        self.make_tracker = make_tracker
        self.trackers: dict[str, Any] = {}
        self.current: str | None = None
        self.pending: deque = deque()  # (actuator, mission_index, operating_hours) announced, not yet current
        self.dirty = False

    def tracker(self, act: str):
        if act not in self.trackers:
            self.trackers[act] = self.make_tracker(act)
        return self.trackers[act]

    def announce(self, meta: dict) -> None:
        """A validated ``hd_mission`` record (``/hd/mission``)."""
        self.pending.append((str(meta.get("actuator_id", "unknown")), _float(meta.get("mission_index")),
                             _float(meta.get("operating_hours"))))
        if self.current is None:
            self._next_mission()

    def _next_mission(self) -> None:
        act, mi, hrs = self.pending.popleft()
        self.current = act
        self.tracker(act).mission_index = mi
        self.tracker(act).hours = hrs

    def _finalise(self, out: list) -> None:
        if self.current is not None:
            tr = self.trackers[self.current]
            if tr.windows:
                out.append((self.current, tr.estimate(final=True)))
        self.current = None
        self.dirty = False

    def rows(self, rows: list[dict]) -> list[tuple[str, dict]]:
        """Feed window rows; returns the committed (actuator, estimate) of every mission they closed."""
        out: list[tuple[str, dict]] = []
        for w in rows:
            mi = w.get("mission_index", math.nan)
            if self.current is not None and self.pending and math.isfinite(mi):
                cur = self.trackers[self.current].mission_index
                if mi != cur and any(m == mi for _, m, _h in self.pending):  # the onboard moved on
                    self._finalise(out)
            if self.current is None:
                if self.pending:
                    self._next_mission()
                else:
                    self.current = "unknown"
                    self.tracker("unknown")
            self.trackers[self.current].add_windows([w])
            self.dirty = True
            if w.get("final", 0.0) == 1.0:
                self._finalise(out)
        return out

    def provisional(self) -> tuple[str, dict] | None:
        """(actuator, estimate of the mission so far, on a copy of the filter) when new rows came since the last."""
        if self.dirty and self.current is not None and self.trackers[self.current].windows:
            self.dirty = False
            return self.current, self.trackers[self.current].estimate(final=False)
        return None


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
