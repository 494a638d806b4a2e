"""What the stiffness and friction monitors share: exponentially weighted regression moments with
persistence runs (:class:`EWMonitor`) and the grouped least squares of their reference fits
(:func:`group_ls`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from hd_onboard.detectors.levels import ERROR, OK, WARN, run_lengths


def group_ls(X: np.ndarray, y: np.ndarray, group: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Least squares ``y = a_g + X coef`` with one intercept per ``group`` label (None: one group).

    Solved by de-meaning ``X`` and ``y`` within each group (Frisch-Waugh: the same ``coef`` as the
    regression with one dummy per group). Returns ``(coef, a)`` with ``a`` the sample-weighted mean
    of the group intercepts (for one group: the ordinary intercept).
    """
    if group is None:
        Xd, yd = X - X.mean(axis=0), y - y.mean()
    else:
        _, code = np.unique(group, return_inverse=True)
        cnt = np.bincount(code).astype(float)
        my = np.bincount(code, weights=y) / cnt
        mX = np.column_stack([np.bincount(code, weights=X[:, j]) / cnt for j in range(X.shape[1])])
        Xd, yd = X - mX[code], y - my[code]
    coef, *_ = np.linalg.lstsq(Xd, yd, rcond=None)
    return coef, float(np.mean(y - X @ coef))


class EWMonitor:
    """What the stiffness and friction monitors share: exponentially weighted regression moments
    (forgetting time ``tau_s`` [s]), the persistence runs of their WARN/ERROR lines and the level.

    A subclass sets ``ref`` and implements its moment inputs and solution; ``m`` holds the
    moments carried between blocks.
    """

    n_moments = 0

    def __init__(self, tau_s: float, persistence: int, fs: float):
        self.tau_s = float(tau_s)
        self.persistence = max(1, int(persistence))
        self.ref = None
        self.set_rate(fs)
        self.reset()

    def set_rate(self, fs: float) -> None:
        self.lam = min(1.0, 1.0 / (self.tau_s * fs))

    def reset(self) -> None:
        self.m = np.zeros(self.n_moments)
        self.run_warn = 0
        self.run_error = 0
        self.n_eval = 0

    def _ew_moments(self, X: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Moments after every sample of a block (rows of ``X`` where ``valid``; an invalid sample
        repeats the last moments) and carry the last ones to the next block."""
        n = len(valid)
        M = np.empty((n, self.n_moments))
        lam = self.lam
        if valid.any():
            Mv, _ = lfilter([lam], [1.0, -(1.0 - lam)], X[valid], axis=0, zi=((1.0 - lam) * self.m)[None, :])
            pos = np.cumsum(valid) - 1
            M[:] = np.where((pos >= 0)[:, None], Mv[np.clip(pos, 0, None)], self.m[None, :])
            self.m = Mv[-1].copy()
        else:
            M[:] = self.m[None, :]
        return M

    def _ew_update(self, x: tuple) -> list[float]:
        """Scalar path: fold one sample's moment inputs ``x`` into ``m`` (same recursion as the block;
        plain floats: numpy on a 5-9 element vector costs more than the arithmetic)."""
        lam, k = self.lam, 1.0 - self.lam
        new = [k * a + lam * b for a, b in zip(self.m.tolist(), x)]
        self.m[:] = new
        return new

    def _runs(self, ok: np.ndarray, v: np.ndarray, warn: float, error: float):
        """Block persistence: (cond_warn, cond_error) per sample for the estimate ``v`` where ``ok``."""
        rw = run_lengths(ok & (v > warn), self.run_warn)
        re = run_lengths(ok & (v > error), self.run_error)
        self.run_warn, self.run_error = int(rw[-1]), int(re[-1])
        self.n_eval += int(ok.sum())
        return rw >= self.persistence, re >= self.persistence

    def _runs_one(self, v: float, warn: float, error: float) -> tuple[bool, bool]:
        """Scalar persistence for one evaluable estimate ``v``."""
        self.n_eval += 1
        self.run_warn = self.run_warn + 1 if v > warn else 0
        self.run_error = self.run_error + 1 if v > error else 0
        return self.run_warn >= self.persistence, self.run_error >= self.persistence

    def _not_evaluable(self) -> tuple[float, bool, bool]:
        self.run_warn = self.run_error = 0
        return math.nan, False, False

    def level(self) -> int:
        """Level of the current estimate (persistence applied): OK / WARN / ERROR."""
        if self.run_error >= self.persistence:
            return ERROR
        if self.run_warn >= self.persistence:
            return WARN
        return OK
