"""The per-actuator prognosis pipeline, from an actuator's bags: features -> Archard PF -> RUL per mission.

* :func:`extract_actuator` reads every bag of one actuator (contract topics
  only; ``/sim/health`` only with ``include_truth=True``, which the
  evaluation code alone passes) and computes each mission's observation
  exactly as the prognostic node does: the onboard node's 1 s feature
  windows reduced by ``hd_onboard.features.mission_observation`` (median
  health features, summed Archard exposure ``W_load``).
* :func:`fit_population` fits the observation model and the Archard prior
  on *training* actuators (their ``/sim/health`` wear is calibration data).
* :func:`prognose` runs the particle filter over one actuator's missions in
  ``mission_index`` order and predicts the RUL in missions at each one.

Step convention: the state is the wear at the *start* of mission k (what
``/sim/health`` reports); step k first propagates with the load-sliding
integral of mission k-1, then updates with mission k's feature. A missing
or unreadable mission is a predict-only step whose exposure is bootstrapped
from the actuator's own past missions.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hd_prognostic.models import ArchardWear
from hd_prognostic.observation import ObservationModel
from hd_prognostic.tracking import RULHistory, track

TOPIC_HEALTH = "/sim/health"
_DRIFT_BLOCK = 10  # missions per block when measuring the drift of the wear coefficient
_SIGMA_LK_FLOOR = 0.003  # per mission: a 10 % change of kappa over ~100 missions stays trackable
DEFAULT_OBS_MODEL = Path(__file__).with_name("default_obs_model.json")


@dataclass
class ActuatorData:
    """Per-mission features of one actuator (plus wear truth when the caller is evaluation code)."""

    actuator_id: str
    paths: list[str] = field(default_factory=list)
    mission_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    operating_hours: np.ndarray = field(default_factory=lambda: np.zeros(0))
    features: list[dict] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)  # bags that could not be used, with the reason
    h_true: np.ndarray | None = None  # m, /sim/health h at mission start (evaluation only)
    h_fail: float = float("nan")  # m, from /sim/health (evaluation only)

    def feature(self, name: str) -> np.ndarray:
        return np.array([f.get(name, np.nan) for f in self.features], float)

    def to_json(self) -> dict:
        d = {"actuator_id": self.actuator_id, "paths": self.paths, "mission_index": self.mission_index.tolist(),
             "operating_hours": self.operating_hours.tolist(), "errors": self.errors,
             "features": [{k: v for k, v in f.items() if k != "notes"} for f in self.features]}
        if self.h_true is not None:
            d["h_true"] = self.h_true.tolist()
            d["h_fail"] = self.h_fail
        from hd_bag.jsonsafe import json_safe

        return json.loads(json.dumps(json_safe(d), default=float))

    @classmethod
    def from_json(cls, d: dict) -> "ActuatorData":
        feats = [{k: (np.nan if v is None else v) for k, v in f.items()} for f in d["features"]]
        a = cls(d["actuator_id"], d["paths"], np.asarray(d["mission_index"], int),
                np.asarray(d["operating_hours"], float), feats, d.get("errors", []))
        if "h_true" in d:
            a.h_true = np.array([np.nan if v is None else v for v in d["h_true"]], float)
            a.h_fail = float(d["h_fail"]) if d["h_fail"] is not None else float("nan")
        return a

    def eol_mission(self) -> float:
        """Truth: the first mission whose start wear reaches h_fail (NaN if none; evaluation only)."""
        if self.h_true is None or not np.isfinite(self.h_fail):
            return float("nan")
        i = np.flatnonzero(self.h_true >= self.h_fail)
        return float(self.mission_index[i[0]]) if len(i) else float("nan")


def _mission_bags(d: Path) -> list[Path]:
    """One actuator's bags in ``d``: ``*.mcap`` files, plus the ``.mcap`` inside each ``ros2 bag``
    directory (a sub-folder with ``metadata.yaml``, as ``ros2 bag record`` and ``rosbags`` write)."""
    bags = [p for p in d.glob("*.mcap") if p.is_file()]
    bags += [p for p in d.glob("*/*.mcap") if p.is_file() and (p.parent / "metadata.yaml").is_file()]
    return sorted(bags)


def find_bags(bag_dir: str | os.PathLike) -> list[Path]:
    d = Path(bag_dir)
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: not a directory")
    bags = _mission_bags(d)
    if not bags:
        raise FileNotFoundError(f"{d}: no .mcap bags (neither *.mcap nor ros2 bag folders with metadata.yaml)")
    return bags


def find_actuator_groups(fleet_dir: str | os.PathLike) -> list[tuple[str, list[Path]]]:
    """Each actuator's (name, bags) in a fleet folder: one sub-folder per actuator (the layout ``hdphm sim fleet``
    writes; the name is the folder's), or, where the folder holds the bags themselves (another tool's flat layout),
    its bags grouped by the ``actuator_id`` of their metadata. A bag whose metadata cannot be read stays with the
    folder's one actuator (its reader skips it with a note); among several actuators it is skipped with a warning
    (whose it is cannot be told)."""
    d = Path(fleet_dir)
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: not a directory")
    dirs = sorted(p for p in d.iterdir() if p.is_dir() and not (p / "metadata.yaml").is_file() and _mission_bags(p))
    flat = _mission_bags(d)
    if dirs and flat:
        raise ValueError(f"{d}: holds both actuator folders ({dirs[0].name}, ...) and bags of its own "
                         f"({flat[0].name}, ...): one layout per fleet folder")
    if dirs:
        return [(p.name, _mission_bags(p)) for p in dirs]
    if not flat:
        raise FileNotFoundError(f"{d}: no .mcap bags (neither actuator folders holding bags nor bags of its own)")
    from hd_bag.mcapio import read_metadata

    groups: dict[str, list[Path]] = {}
    unread: list[tuple[Path, str]] = []
    for b in flat:
        try:
            aid = str(read_metadata(b).get("hd_mission", {}).get("actuator_id", "")).strip()
        except Exception as e:  # noqa: BLE001 - any unreadable bag is named, never a traceback
            unread.append((b, f"{type(e).__name__}: {e}"))
            continue
        if not aid:
            unread.append((b, "no actuator_id in its hd_mission metadata"))
            continue
        groups.setdefault(aid, []).append(b)
    if len(groups) <= 1:
        # one actuator's folder: a bag without readable metadata stays with it, and the reader skips it with a note
        return [(next(iter(groups), d.name), flat)]
    print(f"note: {d}: bags grouped by their metadata's actuator_id ({len(groups)} actuators, no actuator "
          "folders)", file=sys.stderr)
    for b, why in unread:  # whose it is cannot be told: not used, said so
        print(f"warning: skipping {b}: cannot tell its actuator ({why})", file=sys.stderr)
    return sorted(groups.items())


def extract_actuator(bag_dir: str | os.PathLike, *, include_truth: bool = False, cfg=None,
                     cache: str | os.PathLike | None = None, progress: bool = False,
                     bags: list[Path] | None = None) -> ActuatorData:
    """Features of every bag in ``bag_dir`` (one actuator), sorted by ``mission_index``.

    Unreadable bags are skipped and listed in ``errors`` (file and reason);
    bags of another actuator raise. ``cache`` (a JSON file) stores the
    result keyed by the bag list, sizes and mtimes.
    """
    from hd_bag import BagError, read_mission
    from hd_onboard.features import OBS_WINDOW_S, mission_observation_features

    bags = find_bags(bag_dir) if bags is None else sorted(Path(b) for b in bags)
    from hd_onboard import features as _feat

    key = [[str(b), b.stat().st_size, b.stat().st_mtime_ns] for b in bags] + [
        include_truth, list(_feat.FEATURE_NAMES), f"mission_observation v2 (coherent orders) of {OBS_WINDOW_S} s onboard windows",
        "second copies of a recording dropped"]
    if cache and Path(cache).exists():
        try:
            d = json.loads(Path(cache).read_text())
            if d.get("key") == json.loads(json.dumps(key)):
                return ActuatorData.from_json(d["data"])
        except (json.JSONDecodeError, KeyError, TypeError):
            pass
    rows, errors, truth, h_fail, aid, ident = [], [], [], [], None, []
    for i, b in enumerate(bags):
        try:
            m = read_mission(b, include_sim=include_truth)
        except (BagError, ValueError, OSError) as e:
            errors.append(f"{b}: {e}")
            print(f"warning: skipping {b}: {e}", file=sys.stderr)
            continue
        for x in getattr(m.report, "suspect", []):
            errors.append(f"{b}: suspect data (used anyway): {x}")
            print(f"warning: {b}: suspect data: {x}", file=sys.stderr)
        if aid is None:
            aid = m.meta.actuator_id
        elif m.meta.actuator_id != aid:
            raise ValueError(f"{b}: actuator_id {m.meta.actuator_id!r} differs from {aid!r} in the same folder (one "
                             "actuator per folder; 'hdphm prognose --unit ID' picks one from a folder of several)")
        try:
            f = mission_observation_features(m)
        except ValueError as e:
            errors.append(f"{b}: {e}")
            continue
        f["path"] = str(b)
        f["gear_ratio"] = float(m.meta.gear_ratio)  # the observation model holds for one transmission type
        rows.append(f)
        ident.append((int(m.meta.mission_index), _recording_digest(m)))
        if include_truth:
            hh = m.sim.get(TOPIC_HEALTH, {})
            truth.append(float(hh.get("h", np.nan)))
            h_fail.append(float(hh.get("h_fail", np.nan)))
        if progress and (i % 10 == 0 or i == len(bags) - 1):
            print(f"  {bag_dir}: {i + 1}/{len(bags)} bags", flush=True)
    if not rows:
        raise ValueError(f"{bag_dir}: no usable bag ({'; '.join(errors[:3])})")
    o = np.lexsort(([r["path"] for r in rows], [r["operating_hours"] for r in rows],
                    [r["mission_index"] for r in rows]))
    rows = [rows[i] for i in o]
    ident = [ident[i] for i in o]
    # the same recording twice (a copied bag: same mission_index and samples, _recording_digest): one kept, said so
    seen: dict[tuple, str] = {}
    keep = []
    for j, (r, idn) in enumerate(zip(rows, ident)):
        if idn in seen:
            msg = (f"{bag_dir}: {r['path']} is a second copy of mission {idn[0]} ({seen[idn]}: the same samples); "
                   "one kept")
            print(f"warning: {msg}", file=sys.stderr)
            errors.append(msg)
            continue
        seen[idn] = r["path"]
        keep.append(j)
    if len(keep) < len(rows):
        o = np.asarray(o)[keep]
        rows = [rows[j] for j in keep]
    mi = np.array([r["mission_index"] for r in rows], int)
    if np.any(np.diff(mi) == 0):
        # bags from other tools may repeat mission_index: keep (index, hours, file) order, renumber, say so
        dup = [rows[i + 1]["path"] for i in np.flatnonzero(np.diff(mi) == 0)]
        msg = (f"{bag_dir}: duplicate mission_index in {len(dup)} bags (e.g. {dup[0]}); ordered by "
               f"(mission_index, operating_hours, file name) and renumbered 0..{len(rows) - 1}")
        print(f"warning: {msg}", file=sys.stderr)
        errors.append(msg)
        mi = np.arange(len(rows))
        for r, k in zip(rows, mi):
            r["mission_index"] = int(k)
    oh = np.array([r["operating_hours"] for r in rows], float)
    back = np.flatnonzero(np.diff(oh) < 0)
    if len(back):
        # another tool's counters disagree: the filter follows mission_index; say where hours run back
        i = int(back[0])
        msg = (f"{bag_dir}: operating_hours decrease along mission_index in {len(back)} places (e.g. mission "
               f"{int(mi[i])}: {oh[i]:g} h -> mission {int(mi[i + 1])}: {oh[i + 1]:g} h, {rows[i + 1]['path']}); "
               "missions ordered by mission_index, hours not used for the order")
        print(f"warning: {msg}", file=sys.stderr)
        errors.append(msg)
    a = ActuatorData(aid, [r["path"] for r in rows], mi, oh, rows, errors)
    if include_truth:
        a.h_true = np.asarray(truth)[o]
        hf = np.asarray(h_fail)
        a.h_fail = float(np.nanmedian(hf)) if np.isfinite(hf).any() else float("nan")
    if cache:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        Path(cache).write_text(json.dumps({"key": key, "data": a.to_json()}))
    return a


def _recording_digest(m) -> str:
    """A digest of one recording's samples (stamps, angles, torques): equal for two copies of a bag, different for
    two recordings, even when another tool gives both the same mission_index and start stamp."""
    import hashlib

    h = hashlib.blake2b(digest_size=16)
    h.update(str((int(getattr(m, "t0_ns", 0) or 0), int(m.n))).encode())
    for name in ("t", "theta_m", "theta_f", "tau_m", "Q_red"):
        v = getattr(m, name, None)
        if v is not None:
            h.update(np.ascontiguousarray(v, dtype=np.float64).tobytes())
    return h.hexdigest()


def _feature_dict(a: ActuatorData) -> dict[str, np.ndarray]:
    names = set().union(*(f.keys() for f in a.features)) if a.features else set()
    return {k: a.feature(k) for k in names if k not in ("notes", "path", "actuator_id", "torque_source", "gear_ratio")}


def fit_population(train: list[ActuatorData], feature: str = "HF_MTW_IF", degree: int = 2,
                   baseline: str = "subtract", n_baseline: int = 3,
                   fuse: list[str] | None = None, kappa_lifetime: bool = False,
                   predictive_prior: bool = False) -> ObservationModel:
    """Observation model and Archard prior from training actuators (which carry wear truth).

    * obs: pooled (h_true, normalised feature) pairs, heteroscedastic fit.
    * prior: per actuator kappa_i = total wear growth / total W (ln-mean and
      ln-std across actuators: the unit-to-unit scatter); sigma_proc from the
      scatter of per-mission increments around kappa_i W_k; h0 from the
      first-mission wear; h_fail the population median.
    """
    hs, ys, lk, lres, h0, hf, Ws, drift = [], [], [], [], [], [], [], []
    tmp = ObservationModel(feature=feature, baseline=baseline, n_baseline=n_baseline)
    if fuse:
        for a in train:
            if a.h_true is None:
                raise ValueError(f"{a.actuator_id}: training actuators need wear truth (include_truth=True)")
        X = np.vstack([np.column_stack([tmp.normalise(a.feature(f)) for f in fuse]) for a in train])
        coef = ObservationModel.fit_fusion(np.concatenate([a.h_true for a in train]), X)
        tmp.fusion_features, tmp.fusion_coef = list(fuse), [float(c) for c in coef]
        feature = "HI_fused"
    for a in train:
        if a.h_true is None:
            raise ValueError(f"{a.actuator_id}: training actuators need wear truth (include_truth=True)")
        y = tmp.series(_feature_dict(a))
        hs.append(a.h_true)
        ys.append(y)
        W = a.feature("W_load")
        Ws.append(W[np.isfinite(W)])
        dh = np.diff(a.h_true)
        Wp = W[:-1]
        ok = np.isfinite(dh) & np.isfinite(Wp) & (Wp > 0) & (dh > 0)
        if ok.sum() >= 3:
            kap = dh[ok].sum() / Wp[ok].sum()
            lk.append(np.log(kap))
            lres.append(np.log(dh[ok] / (kap * Wp[ok])))
            # drift of the wear coefficient over life: ln kappa of consecutive 10-mission blocks
            nb = int(ok.sum()) // _DRIFT_BLOCK
            if nb >= 2:
                dk = dh[ok][: nb * _DRIFT_BLOCK].reshape(nb, -1).sum(1)
                wk = Wp[ok][: nb * _DRIFT_BLOCK].reshape(nb, -1).sum(1)
                drift.append(np.diff(np.log(dk / wk)))
        h0.append(a.h_true[0])
        hf.append(a.h_fail)
    groups = np.concatenate([np.full(len(h_), i) for i, h_ in enumerate(hs)])
    obs = ObservationModel.fit(np.concatenate(hs), np.concatenate(ys), feature=feature, degree=degree,
                               baseline=baseline, n_baseline=n_baseline, h_fail=float(np.nanmedian(hf)),
                               groups=groups)
    obs.fusion_features, obs.fusion_coef = tmp.fusion_features, tmp.fusion_coef
    if not lk:
        raise ValueError("fit_population: no training actuator has enough wear increments for the Archard prior")
    lres = np.concatenate(lres)
    obs.degradation = {
        "log_kappa_mean": float(np.mean(lk)),
        "log_kappa_std": float(max(np.std(lk), 0.1)),
        "sigma_proc": float(np.clip(1.4826 * np.median(np.abs(lres - np.median(lres))), 0.02, 1.0)),
        "h0_mean": float(np.mean(h0)),
        "h0_std": float(max(np.std(h0), 1e-8)),
        "h_fail": float(np.nanmedian(hf)),
        "h_fail_std": float(np.nanstd(hf)) if len(hf) > 2 else 0.0,
        "W_median": float(np.median(np.concatenate(Ws))) if Ws else float("nan"),
        # random-walk std of ln kappa per mission: block-to-block drift of the training units, floored so a
        # unit whose wear law drifts (lubrication, other effects) can still be followed
        "sigma_log_kappa_fit": float(np.clip(np.sqrt(np.mean(np.concatenate(drift) ** 2) / (2 * _DRIFT_BLOCK))
                                         if drift else 0.02, _SIGMA_LK_FLOOR, 0.1)),
        "n_train": len(train),
        "kappa_lifetime": bool(kappa_lifetime),
        # the fitted drift is used with kappa_lifetime; the first version's 0.02 otherwise
        "predictive_prior": bool(predictive_prior),
    }
    obs.degradation["sigma_log_kappa"] = (obs.degradation["sigma_log_kappa_fit"] if kappa_lifetime else 0.02)
    Ns = gear_ratios(train)
    if Ns:
        obs.fit_info["gear_ratio"] = Ns  # transmission types the fit has seen (prognose notes others)
    return obs


def gear_ratios(acts: list[ActuatorData]) -> list[float]:
    """The transmission types (metadata gear ratios N) of the actuators' bags, sorted: what a fitted model records
    in ``fit_info["gear_ratio"]`` so that a prognosis can name an actuator of another type."""
    return sorted({float(v) for a in acts for v in a.feature("gear_ratio") if np.isfinite(v)})


def other_transmission(a: ActuatorData, fitted: list[float] | None) -> list[float] | None:
    """The actuator's gear ratios when one of them is not among those a model was ``fitted`` on (None: same type,
    or either side unknown)."""
    own = gear_ratios([a])
    if fitted and own and any(min(abs(n - f) for f in fitted) > 1e-6 * n for n in own):
        return own
    return None


def build_model(obs: ObservationModel, h_fail: float | None = None, sigma_log_kappa: float | None = None,
                offset_mode: str = "rb", kappa_lifetime: bool = False) -> ArchardWear:
    """The Archard model with ``obs`` attached and the prior stored in ``obs.degradation``.

    With ``obs.baseline == "state"`` the per-unit feature offset is part of
    the state: marginalised per particle (``offset_mode="rb"``, for the
    particle filter) or one plain state column (``"state"``, for the UKF).
    """
    deg = dict(obs.degradation)
    if not deg:
        raise ValueError("observation model has no 'degradation' prior (fit it with fit_population)")
    hf = float(h_fail if h_fail is not None else deg.get("h_fail", obs.h_fail))
    if sigma_log_kappa is None:  # fitted on the training fleet; 0.02 for files written before it was
        sigma_log_kappa = float(deg.get("sigma_log_kappa", 0.02))
    off = obs.baseline == "state"
    if off and not obs.offset_std > 0:
        raise ValueError("observation model with baseline 'state' has no offset prior (offset_std must be > 0; "
                         "fit it with fit_population)")
    n_tr = int(deg.get("n_train", 0))
    t_prior = bool(deg.get("predictive_prior", False)) and n_tr >= 3
    lk_std = deg["log_kappa_std"] * (np.sqrt(1.0 + 1.0 / n_tr) if t_prior else 1.0)
    return ArchardWear(h_fail=hf, log_kappa_mean=deg["log_kappa_mean"], log_kappa_std=lk_std,
                       log_kappa_df=float(n_tr - 1) if t_prior else float("inf"),
                       h0_mean=deg["h0_mean"], h0_std=deg["h0_std"], sigma_proc=deg["sigma_proc"],
                       sigma_log_kappa=sigma_log_kappa, observe_fn=obs,
                       h_fail_std=float(deg.get("h_fail_std", 0.0)) if h_fail is None else 0.0,
                       offset_mean=obs.offset_mean if off else 0.0, offset_std=obs.offset_std if off else 0.0,
                       offset_mode=offset_mode, kappa_lifetime=bool(deg.get("kappa_lifetime", kappa_lifetime)))


def mission_sequence(a: ActuatorData, obs: ObservationModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mission index per step, observation per step, exposure per step) with gaps filled predict-only.

    Missing mission indices become steps with NaN observation; their
    exposure (and any NaN W) is the median of the actuator's W so far (the
    population median before the first).
    """
    mi = a.mission_index
    full = np.arange(mi[0], mi[-1] + 1)
    y = np.full(len(full), np.nan)
    W = np.full(len(full), np.nan)
    pos = mi - mi[0]
    y[pos] = obs.series(_feature_dict(a))
    W[pos] = a.feature("W_load")
    w_pop = float(obs.degradation.get("W_median", np.nan))
    for k in range(len(W)):  # causal fill (over missions, not samples)
        if not np.isfinite(W[k]) or W[k] < 0:
            past = W[:k][np.isfinite(W[:k])]
            W[k] = np.median(past) if len(past) else w_pop
    if not np.all(np.isfinite(W)):
        raise ValueError(f"{a.actuator_id}: no load-sliding integral available (no Q/tau_m data, no population W)")
    expo = np.concatenate([[0.0], W[:-1]])  # step k uses the wear of mission k-1
    return full.astype(float), y, expo


def _hours_per_mission(hours: np.ndarray, mission_index: np.ndarray) -> float | None:
    """Median operating hours per mission over the forward steps (None when the hours never advance)."""
    if len(hours) < 2:
        return None
    r = np.diff(hours) / np.diff(mission_index)
    r = r[np.isfinite(r) & (r > 0)]
    return float(np.median(r)) if len(r) else None


PF_DEFAULTS = dict(likelihood="student_t", roughening=0.05, kernel="gordon", discount=0.98)


def pf_settings(obs: ObservationModel, likelihood: str = "student_t", pf_options: dict | None = None) -> dict:
    """ParticleFilter keyword arguments of the mission-step filter, batch (:func:`prognose`) and node
    (:class:`hd_prognostic.tracker.ActuatorTracker`) alike: :data:`PF_DEFAULTS`, the Liu-West kernel
    when the observation model's prior is per lifetime (``kappa_lifetime``), then ``pf_options``."""
    return {**PF_DEFAULTS, "likelihood": likelihood,
            **({"kernel": "liu_west"} if obs.degradation.get("kappa_lifetime") else {}),
            **(pf_options or {})}
#: the joint estimator (offset state, Liu-West kernel, h = kappa U, predictive prior): better wear
#: tracking, RUL accuracy not better (README "Joint offset estimator")
JOINT = dict(baseline="state", kappa_lifetime=True, predictive_prior=True, pf_options={"kernel": "liu_west"})


def prognose(a: ActuatorData, obs: ObservationModel, *, n_particles: int = 2000, seed: int = 0,
             likelihood: str = "student_t", max_missions: int = 2000, t_start: float | None = None,
             progress: bool = False, rul_particles: int | None = None,
             snapshots: tuple[int, ...] = (), pf_options: dict | None = None) -> RULHistory:
    """Particle-filter prognosis over one actuator's missions; RUL in missions at every mission.

    ``pf_options`` override :func:`pf_settings` (ParticleFilter keyword arguments).
    """
    model = build_model(obs)
    t, y, expo = mission_sequence(a, obs)

    def future(k: int):
        past = expo[1: k + 1]
        past = past[np.isfinite(past) & (past > 0)]
        return past if len(past) >= 3 else float(obs.degradation.get("W_median", np.nan))

    hist = track(model, t, y, expo, future, rul_step=1.0, max_steps=max_missions,
                 t_start=t[0] if t_start is None else t_start, unit=a.actuator_id,
                 pf_kwargs={**pf_settings(obs, likelihood, pf_options), "n_particles": n_particles, "seed": seed},
                 progress=progress, rul_particles=rul_particles, snapshots=snapshots)
    hours = a.operating_hours
    notes = []
    w_own = a.feature("W_load")
    w_own = w_own[np.isfinite(w_own) & (w_own > 0)]
    w_pop = float(obs.degradation.get("W_median", np.nan))
    if len(w_own) and np.isfinite(w_pop) and w_pop > 0:
        ratio = float(np.median(w_own)) / w_pop
        if not 1 / 3 <= ratio <= 3:
            # RUL is counted in missions: until 3 missions are seen the future missions are
            # population missions, then this actuator's own, so a mission type unlike the
            # training fleet's (shorter, gentler) makes the RUL in missions jump; say so.
            notes.append(f"this actuator's missions carry {ratio:.3g} x the median load-sliding work W_load of the "
                         f"population the observation model was fitted on ({np.median(w_own):.4g} J vs {w_pop:.4g} J):"
                         " the RUL counts population-sized missions until 3 missions are seen, then this "
                         "actuator's own, so expect a step in the RUL there")
    Ns_fit = obs.fit_info.get("gear_ratio")
    Ns_own = other_transmission(a, Ns_fit)
    if Ns_own:
        notes.append(f"gear ratio N = {Ns_own} differs from the N = {Ns_fit} the observation model was fitted on: "
                     "the feature-to-wear map and the wear prior belong to another transmission; refit it on this "
                     "type ('hdphm prognostic fit-obs') before trusting the RUL")
    y_ok = np.isfinite(y)
    if (~y_ok).any():
        notes.append(f"{int((~y_ok).sum())} of {len(y)} steps have no health observation (missing mission index, "
                     f"unreadable bag or {obs.feature} not computable: too short, standstill or outside the "
                     "feature's speed band); the filter only predicts there")
    hist.meta.update({
        "notes": notes,
        "actuator_id": a.actuator_id, "feature": obs.feature, "n_bags": len(a.paths), "skipped_bags": a.errors,
        "hours_per_mission": _hours_per_mission(hours, a.mission_index),
        "likelihood": likelihood,
    })
    return hist


# --------------------------------------------------------------- life model from operator records ---
def unit_history(a: ActuatorData, feature: str = "HF_MTW_IF", exposure: str = "load"):
    """One actuator's health-indicator history for :mod:`hd_prognostic.lifemodel` (contract data only).

    ``exposure``: ``missions`` (E at the start of mission k = k), ``hours`` (operating hours at the mission
    start, from the bags' metadata) or ``load`` (the Archard load-sliding work ``W_load`` [J] summed over
    the missions before k; a missing mission's W is the median of the unit's own). ``E_next`` is the
    exposure at the start of the mission after the last one (that mission's own W / hours are known).
    """
    from hd_prognostic.lifemodel import EXPOSURES, UnitHistory

    if exposure not in EXPOSURES:
        raise ValueError(f"exposure {exposure!r} is not one of {', '.join(EXPOSURES)}")
    mi = a.mission_index.astype(float)
    y = a.feature(feature)
    if not np.isfinite(y).any():
        raise ValueError(f"{a.actuator_id}: health indicator {feature!r} is never computable in its bags")
    hpm = _hours_per_mission(a.operating_hours, a.mission_index)
    full = np.arange(int(mi[0]), int(mi[-1]) + 1)
    pos = (mi - mi[0]).astype(int)
    if exposure == "missions":
        E = mi.copy()
        E_next = float(mi[-1] + 1)
    elif exposure == "hours":
        h = a.operating_hours.astype(float)
        if hpm is None or not np.all(np.isfinite(h)):
            raise ValueError(f"{a.actuator_id}: operating_hours do not advance: exposure 'hours' unusable")
        E, E_next = h, float(h[-1] + hpm)
    else:
        W = np.full(len(full), np.nan)
        W[pos] = a.feature("W_load")
        good = W[np.isfinite(W) & (W >= 0)]
        if not len(good):
            raise ValueError(f"{a.actuator_id}: no load-sliding integral W_load in any mission: exposure 'load' "
                             "unusable (use --exposure missions or hours)")
        W = np.where(np.isfinite(W) & (W >= 0), W, float(np.median(good)))
        before = float(mi[0]) * float(np.median(good))  # missions flown before the first recorded one
        Ec = before + np.concatenate([[0.0], np.cumsum(W)])
        E, E_next = Ec[pos], float(Ec[-1])
    return UnitHistory(a.actuator_id, mi, y, np.asarray(E, float), discrete=True, E_next=E_next,
                       hours_per_step=hpm, notes=list(a.errors))


def load_fleet_histories(fleet_dir, feature: str = "HF_MTW_IF", exposure: str = "load", cache_dir=None,
                         workers: int = 1, progress: bool = False):
    """Every actuator folder of a fleet -> (ActuatorData list, UnitHistory list); contract topics only."""
    groups = find_actuator_groups(fleet_dir)
    jobs = [(Path(fleet_dir) / name, bags, Path(cache_dir) / f"{name}.contract.features.json" if cache_dir else None)
            for name, bags in groups]
    if workers > 1 and len(jobs) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(workers, len(jobs))) as ex:
            acts = list(ex.map(_extract_contract, jobs))
    else:
        acts = [_extract_contract(j) for j in jobs]
    if progress:
        for a in acts:
            print(f"  {a.actuator_id}: {len(a.paths)} missions", flush=True)
    return acts, [unit_history(a, feature, exposure) for a in acts]


def _extract_contract(job):
    d, bags, cache = job
    return extract_actuator(d, include_truth=False, cache=cache, bags=bags)
