"""The EWMA residual detector: normalisation, EWMA with persistence, per-channel lines.

Pure numpy, streaming, vectorised over the samples of a block (state carried
between blocks), so the onboard node, the batch evaluation, the ground's
threshold calibration and the tests run the same arithmetic.

Per residual channel c (``Q_red`` in N*m, ``twist`` in rad, ...)::

    z_k = (r_k - mu_c) / sigma_c                      normalised residual [-]
    e_k = (1 - lam) e_{k-1} + lam z_k                 EWMA, lam = dt / tau  [-]
    over_warn_k  = |e_k| > h_warn_c   for >= P consecutive samples
    over_error_k = |e_k| > h_error_c  for >= P consecutive samples

The fault level at sample k (:class:`hd_onboard.detectors.levels.LevelLatch`) is ERROR if
``over_error`` held within the last
``hold_s`` seconds, else WARN if ``over_warn`` did, else OK: a flag is raised
only after P = persistence_s / dt samples above the line (a single spike does
not flag) and stays up at least ``hold_s`` (no chattering). Invalid samples
(NaN residual: sensor NaN, dropout) do not move the EWMA: the filter runs on
the valid samples only and holds its value across the invalid ones.

``mu``, ``sigma``, ``h_warn`` and ``h_error`` are per actuator and per channel
(:class:`ChannelThreshold`); the ground node computes them from healthy
missions (``hd_ground.thresholds``, arithmetic :func:`hd_onboard.calibration.robust_threshold`)
and pushes them through the twin core.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from hd_onboard.detectors.levels import run_lengths
from hd_twin.records import ChannelThreshold  # noqa: F401 - the twin state's record, defined there


def ewma(z: np.ndarray, lam: float, e0: float) -> np.ndarray:
    """EWMA of ``z`` (NaN entries skipped: the output holds across them), starting from ``e0``."""
    z = np.asarray(z, float)
    out = np.empty_like(z)
    valid = np.isfinite(z)
    if not valid.any():
        out.fill(e0)
        return out
    zv = z[valid]
    ev, _ = lfilter([lam], [1.0, -(1.0 - lam)], zv, zi=[(1.0 - lam) * e0])
    # forward fill: every sample takes the value of the last valid sample at or before it
    pos = np.cumsum(valid) - 1  # index in ev of the last valid sample at or before each sample
    out[:] = np.where(pos >= 0, ev[np.clip(pos, 0, None)], e0)
    return out

class ChannelDetector:
    """Streaming EWMA + persistence detector of one residual channel."""

    def __init__(self, name: str, threshold: ChannelThreshold, lam: float, persistence: int):
        self.name = name
        self.threshold = threshold
        self.lam = float(lam)
        self.persistence = max(int(persistence), 1)
        self.reset()

    def reset(self) -> None:
        self.e = 0.0
        self.run_warn = 0
        self.run_error = 0

    def step(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Block of residuals -> (z, e, cond_warn, cond_error) per sample."""
        th = self.threshold
        z = (np.asarray(r, float) - th.mu) / th.sigma
        e = ewma(z, self.lam, self.e)
        if len(e):
            self.e = float(e[-1])
        a = np.abs(e)
        rw = run_lengths(a > th.h_warn, self.run_warn)
        re = run_lengths(a > th.h_error, self.run_error)
        if len(e):
            self.run_warn, self.run_error = int(rw[-1]), int(re[-1])
        return z, e, rw >= self.persistence, re >= self.persistence

    def step_one(self, r: float) -> tuple[float, bool, bool]:
        """One residual (scalar, NaN allowed) -> (e, cond_warn, cond_error); same arithmetic as :meth:`step`."""
        th = self.threshold
        z = (r - th.mu) / th.sigma
        if z == z and z not in (math.inf, -math.inf):
            self.e = self.lam * z + (1.0 - self.lam) * self.e
        a = abs(self.e)
        self.run_warn = self.run_warn + 1 if a > th.h_warn else 0
        self.run_error = self.run_error + 1 if a > th.h_error else 0
        return self.e, self.run_warn >= self.persistence, self.run_error >= self.persistence
