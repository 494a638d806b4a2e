"""Speed re-timing: a logged speed put on its angle's time base, in ONE place.

A drive logs its own speed estimate (the encoder angle differenced and low-pass filtered; a logger may
average it over the log period), so the logged speed lags the angle's own rate by a delay ``tau`` that
ground discovery identifies (``hd_ground.discovery.data.speed_timing``, kept only when it lowers the fit
bags' cross-validated error: ``core.choose_speed_timing``). The first-order inverse of that delay is::

    omega_retimed = omega + tau * omega'                                  (retime_value, the equation)

exact for a first-order low-pass at low frequency. Discovery, the twin's batch pre-processing
(:func:`hd_twin.data.preprocess`), the streaming twin (:class:`hd_twin.runtime.StreamingTwin`, used by
the onboard node) and the evaluation of a discovery-written config all call this module, so the found
terms are evaluated on the speeds they were fitted on.

Derivative ``omega'``:

* **batch** (:func:`sg2_derivative`): a centred quadratic Savitzky-Golay fit over ``window_s`` (20 ms)
  per segment (the fit of the first / last window at the segment edges), the filter discovery fitted its
  terms with, so a twin config reproduces discovery's numbers.
* **streaming** (:class:`CausalRetimer`): the same quadratic least-squares fit over the last ``window_s``
  of samples, evaluated at the newest one (only past samples). It has no delay for motion that is
  quadratic over the window; for a sinusoid of frequency f the deviation from the true derivative grows
  as (2 pi f window_s)^2 (measured in ``tests/twin/test_speed_timing.py``: the streamed re-timed speed
  is within a few percent of the batch one in the correction ``tau omega'``), and its white-noise gain is
  about four times the centred fit's. The first samples after a reset use the samples available (3 or
  more; fewer: the speed as logged).

Config entry (``config.json:speed_timing``, written by discovery; absent or empty = speeds as logged,
the behaviour of every model written before it)::

    "speed_timing": {"omega_m": {"tau_s": 0.0037, "se": 0.0001}, "window_s": 0.02}
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

#: Window [s] of the quadratic derivative fit of the re-timing (discovery's derivative window).
DEFAULT_WINDOW_S = 0.02
#: Speeds that can be re-timed and their column in ``hd_twin.data.RAW_INPUTS``.
SPEED_COLUMNS = {"omega_m": 1, "omega_f": 4}


def retime_value(omega, domega, tau: float):
    """The equation: the logged speed on its angle's time base, ``omega + tau omega'`` [rad/s]."""
    return omega + tau * domega


def _window(dt: float, window_s: float) -> int:
    return int(round(window_s / dt)) | 1


def sg2_derivative(x: np.ndarray, t: np.ndarray, seg: np.ndarray, window_s: float) -> np.ndarray:
    """Smoothed time derivative per segment (Savitzky-Golay, quadratic, centred), unit of x per second.

    Segments of 3 samples or more; a window under 5 samples, a segment not longer than it or non-finite
    values: central differences (``np.gradient``). Fewer than 3 samples: NaN."""
    from scipy.signal import savgol_filter

    x = np.asarray(x, float)
    t = np.asarray(t, float)
    seg = np.asarray(seg)
    out = np.full(len(x), np.nan)
    for s in np.unique(seg):
        idx = np.flatnonzero(seg == s)
        if len(idx) < 3:
            continue
        xs, ts = x[idx], t[idx]
        dt = float(np.median(np.diff(ts)))
        w = _window(dt, window_s)
        if w >= 5 and len(idx) > w and np.all(np.isfinite(xs)):
            out[idx] = savgol_filter(xs, w, 2, deriv=1, delta=dt)
        else:
            out[idx] = np.gradient(xs, ts)
    return out


def retime_speed(omega: np.ndarray, t: np.ndarray, seg: np.ndarray, tau: float,
                 window_s: float = DEFAULT_WINDOW_S) -> np.ndarray:
    """A logged speed on its angle's time base (batch): :func:`retime_value` with the centred derivative
    :func:`sg2_derivative`; samples without a derivative are kept as logged."""
    d = sg2_derivative(omega, t, seg, window_s)
    return np.where(np.isfinite(d), retime_value(omega, d, tau), omega)


@functools.lru_cache(maxsize=64)
def _end_weights(n: int, dt_key: str) -> np.ndarray:
    """Weights of the quadratic least-squares fit of ``n`` samples evaluated at the last one (slope)."""
    from scipy.signal import savgol_coeffs

    return savgol_coeffs(n, 2, deriv=1, delta=float(dt_key), pos=n - 1, use="dot")


@dataclass
class SpeedTiming:
    """The re-timing of a model: ``lags`` speed name -> (tau [s], standard error [s]); empty: as logged."""

    lags: dict[str, tuple[float, float]] = field(default_factory=dict)
    window_s: float = DEFAULT_WINDOW_S

    @property
    def active(self) -> bool:
        return bool(self.lags)

    @classmethod
    def from_config(cls, entry: Mapping | None, where: str = "config.json speed_timing") -> "SpeedTiming":
        """From a config entry (None / {}: speeds as logged); ValueError naming ``where`` and the problem."""
        if not entry:
            return cls()
        if not isinstance(entry, Mapping):
            raise ValueError(f"{where}: expected a mapping speed -> {{tau_s, se}}, got {type(entry).__name__}")
        window_s = entry.get("window_s", DEFAULT_WINDOW_S)
        try:
            window_s = float(window_s)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: window_s = {window_s!r} is not a number") from None
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"{where}: window_s must be a positive number of seconds, got {window_s!r}")
        lags = {}
        for k, v in entry.items():
            if k == "window_s":
                continue
            if k not in SPEED_COLUMNS:
                raise ValueError(f"{where}: unknown speed {k!r}; one of {sorted(SPEED_COLUMNS)}")
            if not isinstance(v, Mapping) or "tau_s" not in v:
                raise ValueError(f"{where}.{k}: expected {{'tau_s': seconds, 'se': seconds}}, got {v!r}")
            try:
                tau, se = float(v["tau_s"]), float(v.get("se", float("nan")))
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{k}: tau_s / se must be numbers, got {v!r}") from None
            if not math.isfinite(tau) or abs(tau) >= 0.5 * window_s:
                raise ValueError(f"{where}.{k}: tau_s = {tau!r} must be finite and below half the derivative "
                                 f"window ({0.5 * window_s:g} s): the first-order re-timing does not hold beyond")
            lags[k] = (tau, se)
        return cls(lags, window_s)

    @classmethod
    def from_lags(cls, lags: Mapping[str, float], se: Mapping[str, float] | None = None,
                  window_s: float = DEFAULT_WINDOW_S) -> "SpeedTiming":
        se = se or {}
        return cls({k: (float(v), float(se.get(k, float("nan")))) for k, v in lags.items()}, float(window_s))

    def to_config(self) -> dict:
        """The config entry ({} when inactive)."""
        if not self.active:
            return {}
        out: dict = {k: {"tau_s": tau, "se": se} for k, (tau, se) in self.lags.items()}
        out["window_s"] = self.window_s
        return out

    def apply(self, signals: Mapping[str, np.ndarray], t: np.ndarray, segment: np.ndarray | None = None) -> dict:
        """Signal dict with the listed speeds re-timed (batch, centred derivative); others unchanged."""
        out = dict(signals)
        seg = np.zeros(len(t), int) if segment is None else np.asarray(segment)
        for k, (tau, _) in self.lags.items():
            if k in out:
                out[k] = retime_speed(np.asarray(out[k], float), t, seg, tau, self.window_s)
        return out

    def apply_X(self, X: np.ndarray, t: np.ndarray, segment: np.ndarray | None = None) -> np.ndarray:
        """The twin's raw input rows ``X[n, 7]`` with the listed speed columns re-timed (batch); ``X`` itself
        when inactive (bit-for-bit the logged speeds)."""
        if not self.active:
            return X
        X = np.array(X, dtype=np.float64, copy=True)
        seg = np.zeros(len(X), int) if segment is None else np.asarray(segment)
        for k, (tau, _) in self.lags.items():
            j = SPEED_COLUMNS[k]
            X[:, j] = retime_speed(X[:, j], t, seg, tau, self.window_s)
        return X

    def streamer(self, fs: float, fixed_lag: bool = False) -> "CausalRetimer | CentredRetimer":
        """The streaming re-timing at ``fs`` [Hz]: causal (no delay), or ``fixed_lag`` (the batch derivative,
        each row given out half a window later: :class:`CentredRetimer`)."""
        return CentredRetimer(self, fs) if fixed_lag else CausalRetimer(self, fs)


class CausalRetimer:
    """Streaming re-timing of the raw input rows at rate ``fs`` [Hz]: the derivative is the quadratic fit
    of the last ``window_s`` of samples evaluated at the newest one (past samples only; see the module
    docstring for its error); :meth:`reset` at a segment start. A non-finite speed passes through and
    restarts the history."""

    def __init__(self, timing: SpeedTiming, fs: float):
        if not (fs > 0 and math.isfinite(fs)):
            raise ValueError(f"speed re-timing: sample rate must be a positive number, got {fs!r}")
        self.timing = timing
        self.dt = 1.0 / float(fs)
        self.w = max(3, _window(self.dt, timing.window_s))
        self.cols = [(SPEED_COLUMNS[k], tau) for k, (tau, _) in timing.lags.items()]
        self.reset()

    def reset(self) -> None:
        self.hist = {j: np.zeros(0) for j, _ in self.cols}

    def step(self, X: np.ndarray) -> np.ndarray:
        """Rows ``X[n, 7]`` -> the same rows with the speed columns re-timed (a copy; ``X`` when inactive)."""
        if not self.cols:
            return X
        X = np.array(X, dtype=np.float64, copy=True)
        dt_key = f"{self.dt:.12g}"
        full = _end_weights(self.w, dt_key)
        for j, tau in self.cols:
            x = X[:, j]
            buf = np.concatenate([self.hist[j], x])
            start = len(buf) - len(x)
            k = np.arange(len(buf))
            ok = np.isfinite(buf)
            last_bad = np.maximum.accumulate(np.where(ok, -1, k))
            n_avail = np.where(ok, k - last_bad, 0)[start:]  # finite samples ending at each new row
            d = np.full(len(x), np.nan)
            big = n_avail >= self.w
            if big.any():
                win = np.lib.stride_tricks.sliding_window_view(np.where(ok, buf, 0.0), self.w)
                d[big] = win[(k[start:] - self.w + 1)[big]] @ full
            for i in np.flatnonzero((n_avail >= 3) & ~big):  # the first samples after a reset or a gap
                n, kk = int(n_avail[i]), start + i
                d[i] = float(_end_weights(n, dt_key) @ buf[kk - n + 1:kk + 1])
            X[:, j] = np.where(np.isfinite(d), retime_value(x, d, tau), x)
            self.hist[j] = buf[-(self.w - 1):]
        return X


@functools.lru_cache(maxsize=64)
def _sg2_weights(w: int, dt_key: str):
    """Quadratic Savitzky-Golay first-derivative weights of :func:`sg2_derivative` (centre and edge rows)."""
    from scipy.signal import savgol_coeffs

    from .streamfir import FIRWeights  # noqa: PLC0415

    dt = float(dt_key)
    m = w // 2
    rows = [savgol_coeffs(w, 2, deriv=1, delta=dt, pos=k, use="dot") for k in range(w)]
    return FIRWeights(rows[m], np.array(rows[:m]), np.array(rows[w - m:]), dt)


class CentredRetimer:
    """Fixed-lag streaming re-timing equal to the batch one (:meth:`SpeedTiming.apply_X` on the segment):
    the centred quadratic fit of :func:`sg2_derivative` with its edge rows, each row given out ``lag`` rows
    after it came in (the first ones once ``w + 1`` rows are in); :meth:`flush` gives out the rest at the
    end of a segment. Rows must be finite (the streaming twin holds non-finite inputs before this)."""

    def __init__(self, timing: SpeedTiming, fs: float):
        from .streamfir import CentredFIR, gradient_weights  # noqa: PLC0415

        if not (fs > 0 and math.isfinite(fs)):
            raise ValueError(f"speed re-timing: sample rate must be a positive number, got {fs!r}")
        self.timing = timing
        self.dt = 1.0 / float(fs)
        w = _window(self.dt, timing.window_s)
        wt = _sg2_weights(w, f"{self.dt:.12g}") if w >= 5 else gradient_weights(self.dt)
        self.cols = [(SPEED_COLUMNS[k], tau) for k, (tau, _) in timing.lags.items()]
        self.fir = CentredFIR(wt)
        self.reset()

    @property
    def lag(self) -> int:
        """Rows between a row's arrival and its re-timed value (after the first window)."""
        return self.fir.lag if self.cols else 0

    def reset(self) -> None:
        self.fir.reset()
        self.rows = np.zeros((0, 0))

    def _emit(self, d: np.ndarray) -> np.ndarray:
        k = len(d)
        out, self.rows = self.rows[:k].copy(), self.rows[k:]
        for i, (j, tau) in enumerate(self.cols):
            di = d[:, i]
            out[:, j] = np.where(np.isfinite(di), retime_value(out[:, j], di, tau), out[:, j])
        return out

    def step(self, X: np.ndarray) -> np.ndarray:
        """Rows ``X[n, 7]`` in -> the re-timed rows that became known (oldest first, possibly none)."""
        X = np.asarray(X, dtype=np.float64)
        if not self.cols:
            return X
        self.rows = X.copy() if len(self.rows) == 0 else np.vstack([self.rows, X])
        return self._emit(self.fir.push(X[:, [j for j, _ in self.cols]]))

    def flush(self) -> np.ndarray:
        """The rows not given out yet (end of the segment: the fit of the last window)."""
        if not self.cols or len(self.rows) == 0:
            return np.zeros((0, self.rows.shape[1] if self.rows.ndim == 2 else 0))
        return self._emit(self.fir.flush())
