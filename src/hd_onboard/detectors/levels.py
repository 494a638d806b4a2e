"""Fault levels and their timing: persistence runs and the hold latch.

Levels are the ``diagnostic_msgs/DiagnosticStatus`` ones (OK, WARN, ERROR, STALE). A detector's
per-sample condition becomes a flag only after ``P`` consecutive samples above its line
(:func:`run_lengths`), and a raised level is held at least ``hold_s`` seconds (:class:`LevelLatch`):
the fault level at sample k is ERROR if the ERROR condition held within the last ``hold_s``
seconds, else WARN if the WARN one did, else OK.
"""

from __future__ import annotations

import math

import numpy as np

OK, WARN, ERROR, STALE = 0, 1, 2, 3  # diagnostic_msgs/DiagnosticStatus levels
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}


def run_lengths(b: np.ndarray, carry: int) -> np.ndarray:
    """Length of the run of True ending at each sample (0 where False); ``carry`` continues a run from before."""
    n = len(b)
    idx = np.arange(n)
    last_false = np.maximum.accumulate(np.where(~b, idx, -1))
    run = idx - last_false
    return np.where(last_false < 0, run + carry, run).astype(np.int64)

class LevelLatch:
    """Turns per-sample WARN/ERROR conditions into levels held for ``hold_s`` seconds."""

    def __init__(self, hold_s: float):
        self.hold_s = float(hold_s)
        self.reset()

    def reset(self) -> None:
        self.last_warn = -math.inf  # s, last time the WARN condition held
        self.last_error = -math.inf

    def step(self, t: np.ndarray, cond_warn: np.ndarray, cond_error: np.ndarray) -> np.ndarray:
        """Level (OK/WARN/ERROR) per sample; ``t`` in s, increasing."""
        lw = np.maximum(np.maximum.accumulate(np.where(cond_warn | cond_error, t, -np.inf)), self.last_warn)
        le = np.maximum(np.maximum.accumulate(np.where(cond_error, t, -np.inf)), self.last_error)
        if len(t):
            self.last_warn, self.last_error = float(lw[-1]), float(le[-1])
        lev = np.full(len(t), OK, dtype=np.int8)
        lev[t - lw < self.hold_s] = WARN
        lev[t - le < self.hold_s] = ERROR
        return lev

    def step_one(self, t: float, cond_warn: bool, cond_error: bool) -> int:
        """Level of one sample at time ``t`` [s]; same arithmetic as :meth:`step`."""
        if cond_warn or cond_error:
            self.last_warn = max(self.last_warn, t)
        if cond_error:
            self.last_error = max(self.last_error, t)
        if t - self.last_error < self.hold_s:
            return ERROR
        if t - self.last_warn < self.hold_s:
            return WARN
        return OK
