"""The fleet analysis tasks (pure functions of paths and small dicts; they run on Dask workers).

Per actuator the graph is::

    probe(bag)  ->  calibrate(first K bags)  ->  mission(bag, calibration)  (one per bag, parallel)
                                                      \\-> actuator(all its missions): RUL update + fault classes

* :func:`probe_task` reads a bag's ``hd_mission`` metadata only (no chunk decoding): actuator and mission
  number, so the client can group bags and skip stored missions without reading any data itself;
* :func:`calibrate_task` is the ground calibration of one actuator on its first ``healthy_missions``
  missions: :func:`hd_ground.recalibration.recalibrate` (twin parameters) and
  :func:`hd_ground.references.calibrate_actuator` (adaptive residual thresholds, stiffness and friction
  monitor references), the same functions the ground node uses;
* :func:`mission_task` reads one bag where the worker runs and stores, atomically, its onboard features and
  mission observation (:func:`hd_onboard.features.mission_observation_features`), the twin residual
  statistics and monitor outputs of the onboard core run with the ground calibration
  (:func:`hd_onboard.batch.run_mission`), and the mission's recalibration inputs (the least-squares
  estimates of :func:`hd_ground.recalibration.recalibrate` on that mission alone: which parameters move);
* :func:`actuator_task` updates the actuator's RUL history (:func:`hd_prognostic.pipeline.prognose` over the
  stored mission observations) and its fault-class probabilities (:mod:`hd_ground.fleet.classify`).

Nothing here reads ``/sim``. Every result is a deterministic function of the bags and the options, so a
resumed or re-run analysis writes the same rows.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np


@dataclass
class FleetOptions:
    """Options of a fleet analysis (every one recorded with the calibration)."""

    healthy_missions: int = 3  # first missions of each actuator taken as its healthy reference
    model_dir: str = ""  # twin of the onboard node ("" physics stand-in)
    onboard: dict = field(default_factory=dict)  # OnboardConfig overrides (e.g. {"warmup_s": 1.0})
    obs_model: str = ""  # prognostic observation model JSON ("" the package default)
    n_particles: int = 500  # RUL particle filter
    classifier: str = ""  # fault classifier JSON ("" the package default, if present)
    seed: int = 0
    discover: bool = False  # also run discovery once per actuator type (gear ratio) on reference missions
    discover_units: int = 4  # actuators per type whose first reference mission discovery uses

    def onboard_config(self):
        from hd_onboard.config import OnboardConfig

        try:
            return OnboardConfig(**self.onboard).validate()
        except TypeError as e:
            raise ValueError(f"fleet: bad onboard option {self.onboard}: {e}") from None

    def to_dict(self) -> dict:
        return asdict(self)


def _f(x) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v


def probe_task(path: str) -> dict[str, Any]:
    """``{"bag", "actuator_id", "mission_index", "bytes"}`` from the bag's metadata, or ``{"bag", "error"}``."""
    from hd_bag import read_metadata

    try:
        md = read_metadata(path)
        rec = md.get("hd_mission")
        if rec is None:
            return {"bag": str(path), "error": f"{path}: no hd_mission metadata record (see CONTRACT.md)"}
        return {"bag": str(path), "actuator_id": str(rec["actuator_id"]), "mission_index": int(rec["mission_index"]),
                "gear_ratio": _f(rec.get("gear_ratio")), "bytes": os.path.getsize(path)}
    except (KeyError, ValueError, OSError) as e:
        return {"bag": str(path), "error": f"{path}: {type(e).__name__}: {e}"}


def calibrate_task(paths: list[str], opts: FleetOptions) -> dict[str, Any]:
    """Ground calibration of one actuator from its healthy reference bags (JSON-able dict)."""
    from hd_bag import read_mission
    from hd_ground.recalibration import recalibrate
    from hd_ground.references import calibrate_actuator
    from hd_twin import physics as ph

    t0 = time.perf_counter()
    missions, skipped = [], []
    for p in paths:  # an unreadable reference bag is skipped (and said so), not fatal for the actuator
        try:
            missions.append(read_mission(p))
        except (ValueError, OSError) as e:
            skipped.append(f"{p}: {e}")
    params = ph.TwinParams.from_yaml()
    out: dict[str, Any] = {"reference_bags": [str(p) for p in paths],
                           "reference_missions": [int(m.meta.mission_index) for m in missions],
                           "actuator_id": str(missions[0].meta.actuator_id) if missions else "",
                           "options": opts.to_dict(), "skipped": skipped}
    if not missions:  # no calibration: the missions run with the defaults and the onboard self-calibration
        out["error"] = "no readable reference bag: " + "; ".join(skipped)
        out["recalibration"] = {"skipped": out["error"]}
        out["thresholds"], out["references"] = {}, {}
        return json.loads(json.dumps(out, default=float))
    try:
        new, rep = recalibrate(missions, params)
        out["recalibration"] = rep
        params = new
    except ValueError as e:
        out["recalibration"] = {"skipped": str(e)}
    cal = calibrate_actuator(missions, params, opts.onboard_config(), opts.model_dir or None, log=lambda s: None)
    out["params"] = {k: v for k, v in params.to_dict().items() if k not in ("mu_g", "K_out", "notes")}
    out["thresholds"] = cal["thresholds"]
    out["references"] = cal["references"]
    out["task_s"] = time.perf_counter() - t0
    return json.loads(json.dumps(out, default=float))


def _params(calib: dict | None):
    from hd_twin import physics as ph

    if calib and calib.get("params"):
        return ph.TwinParams.from_dict(calib["params"], "fleet calibration parameters")
    return ph.TwinParams.from_yaml()


def _onboard_core(calib: dict | None, mission, opts: FleetOptions):
    from hd_onboard.core import OnboardCore
    from hd_onboard.detectors.ewma import ChannelThreshold
    from hd_onboard.expected import make_expected

    cfg = opts.onboard_config()
    p = _params(calib)
    if np.isfinite(mission.meta.gear_ratio):
        p = p.with_meta(gear_ratio=mission.meta.gear_ratio)
    th = {c: ChannelThreshold(**d) for c, d in (calib or {}).get("thresholds", {}).items()}
    exp = make_expected(opts.model_dir or None, p, fs_hz=cfg.nominal_fs or 1000.0, log=lambda s: None)
    core = OnboardCore(exp, p, None, th or None, cfg)
    refs = (calib or {}).get("references", {})
    if refs.get("stiffness"):
        core.set_stiffness_reference(refs["stiffness"])
    if refs.get("friction"):
        core.set_friction_reference(refs["friction"])
    return core, p


def _nanstat(v: np.ndarray, fn) -> float:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(fn(v)) if len(v) else math.nan


def analyse_mission(mission, calib: dict | None, opts: FleetOptions) -> dict[str, list[dict]]:
    """The four mission tables (row dicts) of one :class:`hd_bag.Mission` (pure: no store)."""
    from hd_ground.analytics import mission_summary
    from hd_ground.recalibration import FIT_NAMES, recalibrate
    from hd_onboard.batch import run_mission
    from hd_onboard.residuals import RESIDUAL_COLUMNS
    from hd_onboard.features import mission_observation_features

    m = mission
    aid, k = str(m.meta.actuator_id), int(m.meta.mission_index)
    key = {"actuator_id": aid, "mission_index": k}
    core, params = _onboard_core(calib, m, opts)
    res = run_mission(m, core)
    summ = mission_summary(res)
    tab = res["table"]
    stats: dict[str, Any] = dict(key)
    for c in ("Q_red", "twist"):
        stats[f"{c}_mean"] = summ[f"{c}.mean"]
        stats[f"{c}_rms"] = summ[f"{c}.rms"]
        e = tab[:, RESIDUAL_COLUMNS.index(f"e_{c}")] if len(tab) else np.empty(0)
        stats[f"{c}_max_abs_e"] = _nanstat(np.abs(e), np.max)
        stats[f"{c}_n_valid"] = int(np.isfinite(tab[:, RESIDUAL_COLUMNS.index(f"r_{c}")]).sum()) if len(tab) else 0
    sl = tab[:, RESIDUAL_COLUMNS.index("stiff_loss")] if len(tab) else np.empty(0)
    fx = tab[:, RESIDUAL_COLUMNS.index("fric_excess")] if len(tab) else np.empty(0)
    stats.update(stiffness_loss=_nanstat(sl, np.median), stiffness_max_loss=_nanstat(sl, np.max),
                 stiffness_n_eval=int(np.isfinite(sl).sum()), friction_excess=_nanstat(fx, np.median),
                 friction_max_excess=_nanstat(fx, np.max), friction_n_eval=int(np.isfinite(fx).sum()),
                 max_level=int(res["max_level"]))
    try:  # recalibration inputs: this mission's own least-squares estimates (which parameters move)
        _, rep = recalibrate([m], params)
        for n in FIT_NAMES:
            stats[f"recal_{n}"] = _f(rep["estimates"][n])
            stats[f"recal_{n}_se"] = _f(rep["std_errors"][n])
        stats["recal_rows"] = int(rep["rows"])
        stats["recal_rms_before"], stats["recal_rms_after"] = _f(rep["rms_before"]), _f(rep["rms_after"])
    except ValueError:
        for n in FIT_NAMES:
            stats[f"recal_{n}"] = stats[f"recal_{n}_se"] = math.nan
        stats["recal_rows"] = 0
        stats["recal_rms_before"] = stats["recal_rms_after"] = math.nan
    # the monitor laws refitted on this mission alone (same function as the ground's reference fit): how the
    # torsional compliance and the direction-odd friction have moved since the reference missions
    from hd_ground.references import actuator_references

    refs = actuator_references([m], [res], params, opts.onboard_config()) if len(tab) else {}
    st_, fr_ = refs.get("stiffness", {}), refs.get("friction", {})
    stats.update(fit_compliance=_f(st_.get("compliance")), fit_twist_b=_f(st_.get("b")),
                 fit_q_range=_f(st_.get("q_range")), fit_friction_b=_f(fr_.get("b")),
                 fit_friction_scale=_f(fr_.get("scale")))
    try:
        obs = mission_observation_features(m)
    except ValueError:
        obs = {}
    feats = dict(key)
    feats.update({n: _f(v) for n, v in obs.items() if n not in ("actuator_id", "mission_index", "notes")
                  and isinstance(v, (int, float, np.integer, np.floating))})
    events = []
    for stamp_ns, level, which in res["events"]:
        events.append({**key, "t_s": (int(stamp_ns) - int(m.t0_ns)) * 1e-9, "kind": "flag", "name": str(which),
                       "level": int(level), "value": math.nan, "detail": ""})
    lev, msg = res.get("input", (0, ""))
    if lev:
        events.append({**key, "t_s": math.nan, "kind": "input", "name": "onboard_input", "level": int(lev),
                       "value": math.nan, "detail": str(msg)})
    for s in getattr(m.report, "suspect", []):
        events.append({**key, "t_s": math.nan, "kind": "input", "name": "suspect_data", "level": 1,
                       "value": math.nan, "detail": str(s)})
    mrow = {**key, "bag": str(getattr(m.report, "path", "")), "operating_hours": _f(m.meta.operating_hours),
            "samples": int(m.n), "duration_s": _f(m.duration), "fs_hz": _f(m.fs), "gear_ratio": _f(m.meta.gear_ratio),
            "source": str(getattr(m.meta, "source", "")), "max_level": int(res["max_level"]),
            "onset_s": _f(res["onset_s"]) if res["onset_s"] is not None else math.nan,
            "reader_notes": len(getattr(m.report, "notes", [])), "n_events": len(events)}
    return {"missions": [mrow], "features": [feats], "residual_stats": [stats], "events": events}


def mission_task(path: str, store_dir: str, calib: dict | None, opts: FleetOptions) -> dict[str, Any]:
    """Analyse one bag where this worker runs and commit it to the store; returns a small summary."""
    from hd_bag import read_mission
    from hd_ground.fleet.store import FleetStore

    t0 = time.perf_counter()
    delay = float(os.environ.get("HDPHM_FLEET_TASK_DELAY_S", "0") or 0)  # throttle (kill/resume tests)
    if delay > 0:
        time.sleep(min(delay, 60.0))
    st = FleetStore(store_dir)
    m = read_mission(path)
    aid, k = str(m.meta.actuator_id), int(m.meta.mission_index)
    if st.has_mission(aid, k):
        return {"bag": str(path), "actuator_id": aid, "mission_index": k, "stored": False, "reason": "already stored"}
    tables = analyse_mission(m, calib, opts)
    tables["missions"][0]["bag"] = str(path)
    tables["missions"][0]["bag_bytes"] = int(os.path.getsize(path))
    tables["missions"][0]["task_s"] = time.perf_counter() - t0
    stored = st.write_mission(aid, k, tables)
    return {"bag": str(path), "actuator_id": aid, "mission_index": k, "stored": stored,
            "max_level": tables["missions"][0]["max_level"], "task_s": time.perf_counter() - t0,
            "samples": int(m.n), "bytes": int(os.path.getsize(path))}


def discover_task(paths: list[str], store_dir: str, type_key: str, opts: FleetOptions) -> dict[str, Any]:
    """Discovery (:func:`hd_ground.discovery.pipeline.run_discovery`) for one actuator type on reference
    missions of several of its actuators; the report goes to ``STORE/discovery/<type_key>/`` (atomic rename)
    with one ``events`` row per effect found (``kind`` = discovery)."""
    import shutil
    import uuid
    from pathlib import Path

    from hd_ground.discovery.pipeline import run_discovery
    from hd_ground.fleet.store import FleetStore, _table

    import pyarrow.parquet as pq

    t0 = time.perf_counter()
    st = FleetStore(store_dir)
    final = st.root / "discovery" / type_key
    if final.is_dir():
        return {"type": type_key, "stored": False}
    tmp = st.root / "_tmp" / f"disc-{os.getpid()}-{uuid.uuid4().hex}"
    try:
        rep = run_discovery(list(paths), tmp, twin_dir=opts.model_dir or None, plots=False, log=lambda s: None)
        ev = [{"actuator_id": type_key, "mission_index": -1, "t_s": math.nan, "kind": "discovery",
               "name": str(e.get("name", e.get("effect", "?"))), "level": 1 if e.get("confirmed", True) else 0,
               "value": _f(e.get("explained")), "detail": json.dumps(e, default=str)}
              for e in rep.get("effects", [])]
        from hd_ground.fleet.store import EVENT_SCHEMA

        pq.write_table(_table(ev, EVENT_SCHEMA), tmp / "events.parquet")
        final.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(tmp, final)
        except OSError:
            if not final.is_dir():
                raise
        return {"type": type_key, "stored": True, "effects": len(ev), "task_s": time.perf_counter() - t0}
    finally:
        if Path(tmp).exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _actuator_data(store, actuator_id: str):
    """:class:`hd_prognostic.pipeline.ActuatorData` from the stored mission observations (no bag read)."""
    from hd_prognostic.pipeline import ActuatorData

    feats = sorted(store.read_mission_rows(actuator_id, "features"), key=lambda r: r["mission_index"])
    mrows = {r["mission_index"]: r for r in store.read_mission_rows(actuator_id, "missions")}
    rows = []
    for f in feats:
        mr = mrows.get(f["mission_index"], {})
        r = {kk: (math.nan if v is None else v) for kk, v in f.items()}
        r["gear_ratio"] = _f(mr.get("gear_ratio"))
        r["path"] = str(mr.get("bag", ""))
        rows.append(r)
    mi = np.array([r["mission_index"] for r in rows], int)
    oh = np.array([_f(mrows.get(k, {}).get("operating_hours")) for k in mi], float)
    return ActuatorData(actuator_id, [r["path"] for r in rows], mi, oh, rows, [])


def rul_rows(store, actuator_id: str, opts: FleetOptions) -> list[dict]:
    """RUL history of one actuator from its stored observations (the prognostic core, batch)."""
    from hd_prognostic.pipeline import DEFAULT_OBS_MODEL, prognose
    from hd_prognostic.observation import ObservationModel

    a = _actuator_data(store, actuator_id)
    if not len(a.mission_index):
        return []
    obs = ObservationModel.from_json(opts.obs_model or DEFAULT_OBS_MODEL)
    hist = prognose(a, obs, n_particles=int(opts.n_particles), seed=int(opts.seed), rul_particles=None)
    out = []
    risk = None
    for i, t in enumerate(hist.t):
        s = hist.samples[i] if i < len(hist.samples) else None
        if s is not None and len(s):
            risk = float(np.mean(np.asarray(s) <= 10.0))
        out.append({"actuator_id": actuator_id, "mission_index": int(round(t)),
                    "h_mean": _f(hist.state_mean[i][0]) if hist.state_mean else math.nan,
                    "h_p5": _f(hist.state_p5[i][0]) if hist.state_p5 else math.nan,
                    "h_p95": _f(hist.state_p95[i][0]) if hist.state_p95 else math.nan,
                    "observation": _f(hist.z[i]) if i < len(hist.z) else math.nan,
                    "rul_p5": _f(hist.p5[i]) if i < len(hist.p5) else math.nan,
                    "rul_p50": _f(hist.p50[i]) if i < len(hist.p50) else math.nan,
                    "rul_p95": _f(hist.p95[i]) if i < len(hist.p95) else math.nan,
                    "risk_10": risk if risk is not None else math.nan,
                    "h_fail": _f(hist.threshold), "n_missions": len(a.mission_index)})
    return out


def actuator_task(store_dir: str, actuator_id: str, calib: dict | None, opts: FleetOptions, *done) -> dict[str, Any]:
    """RUL update and fault classification of one actuator from what the store holds (``done``: the
    mission tasks this waits for)."""
    from hd_ground.fleet import classify
    from hd_ground.fleet.store import FleetStore

    t0 = time.perf_counter()
    st = FleetStore(store_dir)
    n = len(st.done_missions().get(actuator_id, ()))
    out: dict[str, Any] = {"actuator_id": actuator_id, "missions": n}
    if calib is not None:
        st.write_actuator_table(actuator_id, "calibration", [{
            "actuator_id": actuator_id, "reference_missions": json.dumps(calib.get("reference_missions")),
            "params": json.dumps(calib.get("params")), "thresholds": json.dumps(calib.get("thresholds")),
            "references": json.dumps(calib.get("references")),
            "recalibration": json.dumps(calib.get("recalibration")), "options": json.dumps(calib.get("options"))}])
    try:
        rows = rul_rows(st, actuator_id, opts)
    except ValueError as e:
        rows = []
        out["rul_error"] = str(e)
    st.write_actuator_table(actuator_id, "rul", rows)
    stats = st.read_mission_rows(actuator_id, "residual_stats")
    feats = st.read_mission_rows(actuator_id, "features")
    model = classify.load_classifier(opts.classifier or None)
    crow = classify.classify_history(stats, feats, model, healthy_missions=opts.healthy_missions) if model else []
    st.write_actuator_table(actuator_id, "classification", crow)
    ev = []
    if calib is not None and "estimates" in calib.get("recalibration", {}):
        rec = calib["recalibration"]
        ev.append({"actuator_id": actuator_id, "mission_index": max(calib.get("reference_missions") or [0]),
                   "t_s": math.nan, "kind": "recalibration", "name": "twin_params", "level": 0,
                   "value": _f(rec.get("rms_after")), "detail": json.dumps(rec)})
    if crow:
        last = crow[-1]
        ev.append({"actuator_id": actuator_id, "mission_index": int(last["mission_index"]), "t_s": math.nan,
                   "kind": "fault", "name": str(last["label"]), "level": 0 if last["label"] == "healthy" else 1,
                   "value": _f(last[f"p_{last['label']}"]), "detail": ""})
    st.write_actuator_table(actuator_id, "events", ev)
    out["task_s"] = time.perf_counter() - t0
    return out
