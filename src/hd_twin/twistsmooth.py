"""Smoothing of the output angle for the twist, in ONE place (discovery, batch twin, streaming twin).

The twist w = theta_m / N - theta_f is a small difference of two encoder angles; the output encoder's step
(2 pi / 2^16 = 9.6e-5 rad for 16 bits) is a large fraction of it, and that quantisation error in the
regressor biases a twist-to-torque law fitted on it (errors in variables). Ground discovery therefore may read
the twist through theta_f smoothed by a centred quadratic Savitzky-Golay filter, when the fit bags' cross-
validated error of its Q_red model prefers it (``hd_ground.discovery.core.choose_twist_window``). The Q_red
terms it finds are fitted on that twist, so the twin version it writes carries the smoothing
(``config.json:twist_smoothing``) and the twin evaluates its inputs the same way:

* **batch** (:func:`smooth_angle`, :meth:`TwistSmoothing.apply_X`; discovery's dataset, the twin's
  pre-processing ``hd_twin.data.preprocess``): per gap-free segment, the centred Savitzky-Golay smoother
  (``mode="interp"``: the fit of the first / last window at the segment's edges); a segment not longer than
  the window keeps the logged angle.
* **streaming, fixed lag** (:class:`CentredSmoother`, ``StreamingTwin`` mode ``"fixed_lag"``): the same
  weights, each row given out half a window late, equal to the batch rows.
* **streaming, causal** (:class:`CausalSmoother`, mode ``"causal"``): the same quadratic least-squares fit
  over the last window evaluated at the newest sample (past samples only; no delay for motion quadratic over
  the window, about twice the centred fit's white-noise gain); the first rows after a reset, before a whole
  window is in, keep the logged angle.

Only theta_f is smoothed (theta_m is divided by N, its step with it); speeds, torques and the twist rate are
untouched. The window is stored in seconds and turned into an odd number of samples at the rate the twin
runs on (``round(window_s fs)``, made odd): at discovery's own rate it is discovery's window exactly; a
window of at most ``polyorder + 1`` samples is the identity (the polynomial passes through the samples).

Config entry (absent or empty: theta_f as logged, every model written before it)::

    "twist_smoothing": {"window_s": 0.009, "polyorder": 2}
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

#: Column of theta_f in ``hd_twin.data.RAW_INPUTS``.
THETA_F_COLUMN = 3
#: Longest smoothing window accepted from a config [s]: the twist's own dynamics are faster than this.
MAX_WINDOW_S = 1.0
#: Longest window [samples] the streamers take: the fixed-lag weights (the batch fit's edge rows) hold w^2 numbers, so a
#: window at an absurd input rate (a hostile or mislabelled bag) is refused instead of allocated (4097: 134 MB).
MAX_STREAM_WINDOW = 4097


def window_samples(window_s: float, fs: float) -> int:
    """The window in samples at ``fs`` [Hz]: ``round(window_s fs)``, made odd."""
    return int(round(float(window_s) * float(fs))) | 1


def smooth_angle(x: np.ndarray, segment: np.ndarray | None, window: int, polyorder: int = 2) -> np.ndarray:
    """The equation: ``x`` smoothed per segment by the centred Savitzky-Golay filter of ``window`` samples
    (odd) and ``polyorder``; segments of at most ``window`` samples (and windows of at most ``polyorder + 1``
    samples) keep ``x``. Returns a new array."""
    from scipy.signal import savgol_filter

    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    w = int(window)
    if w % 2 == 0:
        raise ValueError(f"twist smoothing: window must be an odd number of samples, got {window}")
    if w <= polyorder + 1:
        return out
    seg = np.zeros(len(x), int) if segment is None else np.asarray(segment)
    for s in np.unique(seg):
        idx = np.flatnonzero(seg == s)
        if len(idx) > w:
            out[idx] = savgol_filter(x[idx], w, polyorder)
    return out


@dataclass(frozen=True)
class TwistSmoothing:
    """theta_f's smoothing of a model: ``window_s`` [s] (0: as logged) and the polynomial order."""

    window_s: float = 0.0
    polyorder: int = 2

    @property
    def active(self) -> bool:
        return self.window_s > 0

    @classmethod
    def from_config(cls, entry: Mapping | None, where: str = "config.json twist_smoothing") -> "TwistSmoothing":
        """From a config entry (None / {}: as logged); ValueError naming ``where`` and the problem."""
        if not entry:
            return cls()
        if not isinstance(entry, Mapping):
            raise ValueError(f"{where}: expected a mapping {{window_s, polyorder}}, got {type(entry).__name__}")
        unknown = set(entry) - {"window_s", "polyorder"}
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {sorted(unknown)}; expected window_s, polyorder")
        window_s = entry.get("window_s", 0.0)
        if isinstance(window_s, bool) or not isinstance(window_s, (int, float)):
            raise ValueError(f"{where}: window_s = {window_s!r} is not a number (seconds)")
        window_s = float(window_s)
        if not (math.isfinite(window_s) and 0 <= window_s <= MAX_WINDOW_S):
            raise ValueError(f"{where}: window_s must be a number of seconds in [0, {MAX_WINDOW_S:g}], "
                             f"got {entry.get('window_s')!r}")
        p = entry.get("polyorder", 2)
        if isinstance(p, bool) or not isinstance(p, (int, float)) or p != int(p) or not 0 <= int(p) <= 4:
            raise ValueError(f"{where}: polyorder must be an integer 0..4, got {p!r}")
        return cls(window_s, int(p))

    @classmethod
    def from_samples(cls, window: int, fs: float, polyorder: int = 2) -> "TwistSmoothing":
        """Discovery's choice, ``window`` samples at its bag rate ``fs`` [Hz] (0: as logged)."""
        return cls(int(window) / float(fs) if window else 0.0, int(polyorder))

    def to_config(self) -> dict:
        """The config entry ({} when inactive)."""
        return {"window_s": self.window_s, "polyorder": self.polyorder} if self.active else {}

    def samples(self, fs: float) -> int:
        return window_samples(self.window_s, fs) if self.active else 1

    def apply_X(self, X: np.ndarray, fs: float, segment: np.ndarray | None = None) -> np.ndarray:
        """The twin's raw input rows ``X[n, 7]`` at ``fs`` [Hz] with theta_f smoothed (batch); ``X`` itself when
        inactive (bit-for-bit the logged angle)."""
        if not self.active:
            return X
        X = np.array(X, dtype=np.float64, copy=True)
        X[:, THETA_F_COLUMN] = smooth_angle(X[:, THETA_F_COLUMN], segment, self.samples(fs), self.polyorder)
        return X

    def streamer(self, fs: float, fixed_lag: bool = False) -> "CausalSmoother | CentredSmoother":
        """The streaming smoothing at ``fs`` [Hz]: causal (no delay) or ``fixed_lag`` (equal to the batch rows,
        half a window late)."""
        return CentredSmoother(self, fs) if fixed_lag else CausalSmoother(self, fs)


@functools.lru_cache(maxsize=32)
def _weights(w: int, polyorder: int):
    """Savitzky-Golay smoothing weights of :func:`smooth_angle`: centre row and the edge rows of
    ``mode="interp"`` (``hd_twin.streamfir.FIRWeights``; ``dt`` is not used by a smoother)."""
    from scipy.signal import savgol_coeffs

    from .streamfir import FIRWeights  # noqa: PLC0415

    m = w // 2
    rows = [savgol_coeffs(w, polyorder, pos=k, use="dot") for k in range(w)]
    return FIRWeights(rows[m], np.array(rows[:m]), np.array(rows[w - m:]), 1.0)


def _stream_window(smoothing: TwistSmoothing, fs: float) -> int:
    """The streamers' window in samples at ``fs`` [Hz]; ValueError naming the problem for a bad rate or a window
    longer than :data:`MAX_STREAM_WINDOW`."""
    if not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs > 0):
        raise ValueError(f"twist smoothing: sample rate must be a positive number, got {fs!r}")
    w = smoothing.samples(float(fs))
    if w > MAX_STREAM_WINDOW:
        raise ValueError(f"twist smoothing: a {smoothing.window_s:g} s window is {w} samples at {fs:g} Hz, more than "
                         f"the streaming twin takes ({MAX_STREAM_WINDOW})")
    return w


class CentredSmoother:
    """Fixed-lag streaming smoothing of theta_f equal to the batch one (:meth:`TwistSmoothing.apply_X` on the
    segment): rows go in, each comes out ``lag`` rows later (the first ones once ``w + 1`` rows are in);
    :meth:`flush` gives out the rest at the end of a segment (a segment of at most ``w`` rows: as logged).
    Rows must be finite (the streaming twin holds non-finite inputs before this)."""

    def __init__(self, smoothing: TwistSmoothing, fs: float):
        from .streamfir import CentredFIR  # noqa: PLC0415

        self.w = _stream_window(smoothing, fs)
        self.on = smoothing.active and self.w > smoothing.polyorder + 1
        self.fir = CentredFIR(_weights(self.w, smoothing.polyorder), short=lambda x: x.copy()) if self.on else None
        self.reset()

    @property
    def lag(self) -> int:
        return self.fir.lag if self.on else 0

    def reset(self) -> None:
        if self.fir is not None:
            self.fir.reset()
        self.rows = None

    def _emit(self, sm: np.ndarray) -> np.ndarray:
        k = len(sm)
        out, self.rows = self.rows[:k].copy(), self.rows[k:]
        out[:, THETA_F_COLUMN] = sm
        return out

    def step(self, X: np.ndarray) -> np.ndarray:
        """Rows ``X[n, 7]`` in -> the smoothed rows that became known (oldest first, possibly none)."""
        X = np.asarray(X, dtype=np.float64)
        if not self.on:
            return X
        self.rows = X.copy() if self.rows is None or len(self.rows) == 0 else np.vstack([self.rows, X])
        return self._emit(self.fir.push(X[:, THETA_F_COLUMN]))

    def flush(self) -> np.ndarray:
        """The rows not given out yet (end of the segment: the fit of the last window)."""
        if not self.on or self.rows is None or len(self.rows) == 0:
            return np.zeros((0, 0 if self.rows is None else self.rows.shape[1]))
        return self._emit(self.fir.flush())


class CausalSmoother:
    """Causal streaming smoothing of theta_f: the quadratic least-squares fit of the last ``w`` samples
    evaluated at the newest one; rows before a whole window is in since the reset, and a non-finite angle,
    keep the logged value (a non-finite sample restarts the window)."""

    def __init__(self, smoothing: TwistSmoothing, fs: float):
        self.w = _stream_window(smoothing, fs)
        self.on = smoothing.active and self.w > smoothing.polyorder + 1
        if self.on:  # the end-of-window row of the batch fit's weights (only that row: O(w), not w^2)
            from scipy.signal import savgol_coeffs

            self.end = savgol_coeffs(self.w, smoothing.polyorder, pos=self.w - 1, use="dot")
        else:
            self.end = None
        self.reset()

    lag = 0

    def reset(self) -> None:
        self.hist = np.zeros(0)

    def step(self, X: np.ndarray) -> np.ndarray:
        """Rows ``X[n, 7]`` -> the same rows with theta_f smoothed (a copy; ``X`` when inactive)."""
        X = np.asarray(X, dtype=np.float64)
        if not self.on or len(X) == 0:
            return X
        X = X.copy()
        x = X[:, THETA_F_COLUMN]
        buf = np.concatenate([self.hist, x])
        start = len(buf) - len(x)
        k = np.arange(len(buf))
        ok = np.isfinite(buf)
        last_bad = np.maximum.accumulate(np.where(ok, -1, k))
        full = (np.where(ok, k - last_bad, 0) >= self.w)[start:]  # a whole finite window ends at the row
        if full.any():
            win = np.lib.stride_tricks.sliding_window_view(np.where(ok, buf, 0.0), self.w)
            X[full, THETA_F_COLUMN] = win[(k[start:] - self.w + 1)[full]] @ self.end
        self.hist = buf[-(self.w - 1):]
        return X
