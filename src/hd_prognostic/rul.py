"""Remaining-useful-life distribution from a particle set.

Each particle is propagated through the degradation model (with process
noise and the future exposure drawn per particle per step) until it crosses
the failure threshold; the step count times the step length is that
particle's RUL sample. Vectorised over particles; the loop runs over future
steps only, on the particles still alive.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hd_prognostic.models import DegradationModel
from hd_prognostic.pf import weighted_quantile

FutureExposure = float | np.ndarray | Callable[[int, int, np.random.Generator], np.ndarray]


@dataclass
class RULResult:
    """RUL samples (time units of the model: missions, cycles, ...) and their summaries."""

    samples: np.ndarray  # RUL per particle; inf where the horizon was reached first
    weights: np.ndarray  # normalised particle weights
    step: float  # time per propagation step
    horizon: float  # max RUL considered
    time_unit: str = "step"
    quantiles: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        q = weighted_quantile(self.samples, self.weights, [0.05, 0.50, 0.95])  # one sort
        self.quantiles = {"p5": float(q[0]), "p50": float(q[1]), "p95": float(q[2])}
        fin = np.isfinite(self.samples)
        wf = self.weights[fin]
        self.mean = float(np.sum(wf * self.samples[fin]) / wf.sum()) if wf.sum() > 0 else float("inf")
        self.p_beyond_horizon = float(self.weights[~fin].sum())

    @property
    def p5(self) -> float:
        return self.quantiles["p5"]

    @property
    def p50(self) -> float:
        return self.quantiles["p50"]

    @property
    def p95(self) -> float:
        return self.quantiles["p95"]

    def risk(self, t: np.ndarray) -> np.ndarray:
        """Risk-of-failure curve P(RUL <= t) for times ``t`` (same unit as the samples)."""
        t = np.atleast_1d(np.asarray(t, float))
        o = np.argsort(self.samples)
        s, c = self.samples[o], np.cumsum(self.weights[o])
        i = np.searchsorted(s, t, side="right")
        return np.where(i > 0, c[np.maximum(i - 1, 0)], 0.0)

    def summary(self) -> dict:
        return {
            "p5": self.p5, "p50": self.p50, "p95": self.p95, "mean": self.mean,
            "p_beyond_horizon": self.p_beyond_horizon, "time_unit": self.time_unit,
        }


def _draw_exposure(future: FutureExposure, k: int, n: int, rng: np.random.Generator):
    if callable(future):
        return np.asarray(future(k, n, rng), float)
    arr = np.asarray(future, float)
    if arr.ndim == 0:
        return float(arr)
    if arr.size == 0:
        raise ValueError("future exposure history is empty")
    return arr[rng.integers(0, arr.size, n)]  # bootstrap from the history


def rul_distribution(
    model: DegradationModel,
    x: np.ndarray,
    weights: np.ndarray | None = None,
    future: FutureExposure = 1.0,
    step: float = 1.0,
    max_steps: int = 1000,
    rng: np.random.Generator | int | None = 0,
    keep_paths: int = 0,
) -> RULResult | tuple[RULResult, np.ndarray]:
    """RUL samples for particles ``x`` (weights ``weights``).

    ``future`` is the exposure per future step: a scalar, a history array to
    bootstrap from (per particle, per step), or a callable ``(k, n, rng)``.
    ``step`` is the time one step represents. Particles already failed have
    RUL 0; particles alive after ``max_steps`` get ``inf``. With
    ``keep_paths > 0`` also returns the health trajectories of that many
    particles (shape ``(max_steps_run + 1, keep_paths)``), for plots.
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    x = model.check_state(x).copy()
    n = len(x)
    w = np.full(n, 1.0 / n) if weights is None else np.asarray(weights, float) / np.sum(weights)
    fast = getattr(model, "rul_fast", None)
    if fast is not None and not keep_paths:
        r = fast(x, future, float(step), int(max_steps), rng)
        if r is not None:
            return RULResult(r, w, float(step), float(max_steps * step), model.time_unit)
    rul = np.full(n, np.inf)
    rul[model.failed(x)] = 0.0
    alive = np.flatnonzero(~np.isfinite(rul))
    paths = [model.health(x[:keep_paths]).copy()] if keep_paths else None
    xa = x[alive]
    for k in range(1, int(max_steps) + 1):
        if len(alive) == 0 and not keep_paths:
            break
        if len(alive):
            u = _draw_exposure(future, k, len(alive), rng)
            xa = model.propagate(xa, u, rng)
            f = model.failed(xa)
            if f.any():
                rul[alive[f]] = k * step
                alive, xa = alive[~f], xa[~f]
        if keep_paths:
            xp = x[:keep_paths]
            x[:keep_paths] = model.propagate(xp, _draw_exposure(future, k, keep_paths, rng), rng)
            paths.append(model.health(x[:keep_paths]).copy())
            if len(alive) == 0 and np.all(model.failed(x[:keep_paths])):
                break
    res = RULResult(rul, w, float(step), float(max_steps * step), model.time_unit)
    if keep_paths:
        return res, np.array(paths)
    return res
