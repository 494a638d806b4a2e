"""Run a filter over one unit's observation sequence and record the RUL history.

The same loop serves the harmonic-drive actuators (one step per mission),
the NASA battery cells (one step per cycle) and the Virkler specimens (one
step per inspection): ``times[k]`` is the time of observation ``obs[k]``
(NaN = missing: predict-only), ``exposure[k]`` what drove degradation since
the previous observation. A RUL distribution is computed at every step from
``t_start`` on.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hd_prognostic.models import DegradationModel
from hd_prognostic.pf import ParticleFilter, weighted_quantile
from hd_prognostic.rul import FutureExposure, RULResult, rul_distribution


# the RUL distribution of each prediction is stored as the quantiles at the midpoints of 50 equal-probability
# cells, 0.01, 0.03, ..., 0.99: symmetric, each standing for 2 % of the mass, so the mean of the stored values and
# the PIT computed from them are unbiased (the grid 0.01..0.97 used before had no 0.99: means 2-3 % low, PIT +0.01)
QUANTILE_LEVELS = (np.arange(50) + 0.5) / 50


def level_weights(levels) -> np.ndarray:
    """Probability mass each stored quantile stands for: the cell between the midpoints to its neighbours
    (0 and 1 at the ends). Equal (1/n) for the midpoint grid; corrects grids without a symmetric tail."""
    q = np.asarray(levels, float)
    edges = np.concatenate([[0.0], 0.5 * (q[1:] + q[:-1]), [1.0]])
    return np.diff(edges)


@dataclass
class RULHistory:
    """Per-step filter summaries and RUL predictions of one unit."""

    unit: str
    time_unit: str
    t: list[float] = field(default_factory=list)
    z: list[float] = field(default_factory=list)
    state_mean: list[list[float]] = field(default_factory=list)
    state_p5: list[list[float]] = field(default_factory=list)
    state_p95: list[list[float]] = field(default_factory=list)
    ess: list[float] = field(default_factory=list)
    rul_t: list[float] = field(default_factory=list)
    p5: list[float] = field(default_factory=list)
    p50: list[float] = field(default_factory=list)
    p95: list[float] = field(default_factory=list)
    mean: list[float] = field(default_factory=list)
    samples: list[np.ndarray] = field(default_factory=list)  # kept in memory (thinned), not in JSON
    # weights of ``samples`` (one array per prediction); empty = equally weighted (the in-memory draws); set when
    # the samples are the stored quantiles of a JSON history, from their levels (:func:`level_weights`)
    sample_weights: list[np.ndarray] = field(default_factory=list)
    state_names: tuple[str, ...] = ()
    threshold: float = float("nan")
    meta: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = {k: getattr(self, k) for k in ("unit", "time_unit", "t", "z", "state_mean", "state_p5", "state_p95",
                                           "ess", "rul_t", "p5", "p50", "p95", "mean", "threshold")}
        d["meta"] = {k: v for k, v in self.meta.items() if k != "snapshots"}
        d["state_names"] = list(self.state_names)
        # the RUL distribution per prediction as 50 quantiles (QUANTILE_LEVELS, 1 %..99 %, step 2 %):
        # enough for PIT and CRPS when the history is scored later
        if self.samples:
            d["rul_quantile_levels"] = QUANTILE_LEVELS.tolist()
            # RUL samples are +inf where a particle never fails within the horizon; linear
            # interpolation between two inf gives NaN (inf - inf), so such sets use the
            # interpolation-free inverted CDF: the quantile is then honestly +inf.
            d["rul_quantiles"] = [np.quantile(s_, QUANTILE_LEVELS, method="linear" if np.isfinite(s_).all()
                                              else "inverted_cdf").tolist() for s_ in self.samples]
        return _clean(d)

    @classmethod
    def from_json(cls, d: dict) -> "RULHistory":
        h = cls(unit=d["unit"], time_unit=d.get("time_unit", "step"))
        for k in ("t", "z", "state_mean", "state_p5", "state_p95", "ess", "rul_t", "p5", "p50", "p95", "mean"):
            setattr(h, k, [(_unclean(v)) for v in d.get(k, [])])
        h.state_names = tuple(d.get("state_names", ()))
        if "rul_quantiles" in d:
            h.samples = [np.asarray(_unclean(q), float) for q in d["rul_quantiles"]]
            lv = d.get("rul_quantile_levels")
            if lv is not None and len(lv) == len(h.samples[0] if h.samples else lv):
                w = level_weights(lv)
                h.sample_weights = [w.copy() for _ in h.samples]
        h.threshold = _unclean(d.get("threshold"))
        h.meta = d.get("meta", {})
        return h


def _clean(o):
    """JSON-safe: inf/NaN -> strings, numpy -> python."""
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_clean(v) for v in o]
    if isinstance(o, (float, np.floating)):
        f = float(o)
        return f if np.isfinite(f) else ("inf" if f > 0 else "-inf" if f < 0 else "nan")
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def _unclean(o):
    if isinstance(o, list):
        return [_unclean(v) for v in o]
    if o in ("inf", "-inf", "nan"):
        return float(o)
    return o


def track(
    model: DegradationModel,
    times: np.ndarray,
    obs: np.ndarray,
    exposure: np.ndarray,
    future: FutureExposure | Callable[[int], FutureExposure],
    *,
    rul_step: float = 1.0,
    max_steps: int = 1000,
    t_start: float = -np.inf,
    unit: str = "unit",
    pf: ParticleFilter | None = None,
    pf_kwargs: dict | None = None,
    keep_samples: int = 2000,
    rul_particles: int | None = None,
    progress: bool = False,
    snapshots: tuple[int, ...] = (),
) -> RULHistory:
    """Filter ``obs`` and predict RUL at each step with ``times[k] >= t_start``.

    ``future`` is the exposure per future RUL step, or a callable ``k ->
    future`` giving it from the data seen up to step ``k`` (e.g. bootstrap
    from the unit's own past loads). ``rul_particles`` thins the particle set
    for the RUL propagation (default: all).
    """
    times = np.asarray(times, float)
    obs = np.asarray(obs, float)
    exposure = np.asarray(exposure, float)
    if not (len(times) == len(obs) == len(exposure)):
        raise ValueError(f"{unit}: times, obs and exposure lengths differ ({len(times)}, {len(obs)}, {len(exposure)})")
    if len(times) and np.any(np.diff(times) < 0):
        raise ValueError(f"{unit}: observation times are not sorted")
    pf = pf or ParticleFilter(model, **(pf_kwargs or {}))
    hist = RULHistory(unit=unit, time_unit=model.time_unit, state_names=model.state_names,
                      threshold=float(model.threshold))
    t0 = _time.perf_counter()
    snaps: list[dict] = []
    for k in range(len(times)):
        pf.step(exposure[k], obs[k])
        w = pf.weights
        hist.t.append(float(times[k]))
        hist.z.append(float(obs[k]))
        hist.state_mean.append(pf.mean().tolist())
        qs = np.array([weighted_quantile(pf.x[:, j], w, [0.05, 0.95]) for j in range(model.n_states)])
        hist.state_p5.append(qs[:, 0].tolist())
        hist.state_p95.append(qs[:, 1].tolist())
        hist.ess.append(pf.ess())
        if times[k] >= t_start:
            fut = future(k) if callable(future) and _is_step_fn(future) else future
            if rul_particles and rul_particles < pf.n:
                xs, ws = pf.resampled_particles()[:rul_particles], None
            else:
                xs, ws = pf.x, w
            r: RULResult = rul_distribution(model, xs, ws, fut, rul_step, max_steps, pf.rng)
            if k in snapshots:
                _, paths = rul_distribution(model, pf.resampled_particles()[:60], None, fut, rul_step, max_steps,
                                            pf.rng, keep_paths=60)
                snaps.append({"k": k, "t": float(times[k]), "x": pf.x.copy(), "w": w.copy(), "z": float(obs[k]),
                              "rul": r, "paths": paths, "z_hist": obs[: k + 1].copy(),
                              "t_hist": times[: k + 1].copy()})
            hist.rul_t.append(float(times[k]))
            hist.p5.append(r.p5)
            hist.p50.append(r.p50)
            hist.p95.append(r.p95)
            hist.mean.append(r.mean)
            if keep_samples:
                sel = np.random.default_rng(k).choice(len(r.samples), min(keep_samples, len(r.samples)),
                                                      replace=True, p=r.weights)  # equally weighted draws
                hist.samples.append(r.samples[sel])
        if progress and (k % 10 == 0 or k == len(times) - 1):
            print(f"  {unit}: step {k + 1}/{len(times)}  ESS {pf.ess():.0f}  "
                  f"{_time.perf_counter() - t0:.1f} s", flush=True)
    hist.meta["n_resample"] = pf.n_resample
    if snaps:
        hist.meta["snapshots"] = snaps
    hist.meta["n_particles"] = pf.n
    hist.meta["rul_horizon"] = float(rul_step * max_steps)  # RUL = inf means "no failure within this"
    return hist


def _is_step_fn(f) -> bool:
    """A callable future taking one argument (the step index) rather than (k, n, rng)."""
    import inspect

    try:
        return len(inspect.signature(f).parameters) == 1
    except (TypeError, ValueError):
        return False
