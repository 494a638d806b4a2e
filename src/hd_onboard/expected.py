"""Expected response of the actuator: the twin in streaming form, or a physics-only stand-in.

Both take blocks of the twin's raw input matrix ``X[n, 7]`` (columns
``hd_twin.data.RAW_INPUTS``: theta_m rad, omega_m rad/s, tau_m N*m, theta_f
rad, omega_f rad/s, temperature degC, theta_ref rad; NaN allowed) with the
sample times, and return the expected reducer output torque ``Q_red_hat``
[N*m] per sample, carrying their state between blocks; ``reset()`` starts a
new segment (mission start, dropout).

* :class:`OnnxTwinExpected` runs the trained PINN twin
  (``hd_twin.runtime.StreamingTwin(model_dir)``, LSTM state carried).
* :class:`PhysicsStandInExpected` is the **physics-only stand-in**, used when
  no trained twin is given or it cannot be loaded: the twin's own declared
  physics, quasi-static (``hd_twin.physics.quasi_static_Q_red``:
  Q_red = N (Q_res - J_in theta_m'') - J_CS theta_f'' with input friction),
  with theta_m'' and theta_f'' from causal filtered differences of the
  measured speeds. It is a transparent baseline, not the paper's twin, and
  every output of the stack says which one ran.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi

from hd_twin import physics as ph

#: column indices in RAW_INPUTS order
I_THM, I_WM, I_TAU, I_THF, I_WF, I_TEMP, I_REF = range(7)


class CausalDerivative:
    """Streaming derivative: backward difference then a 2nd-order Butterworth low-pass (state carried).

    ``cutoff_hz`` [Hz]; the sample period is taken from the stamps of each
    block (dt per sample), so jittered stamps are handled; NaN inputs are
    held (the derivative is 0 across them).
    """

    def __init__(self, n_ch: int, cutoff_hz: float, fs_hz: float):
        if not (cutoff_hz > 0 and fs_hz > 2 * cutoff_hz):
            raise ValueError(f"derivative filter: cutoff {cutoff_hz} Hz must be in (0, fs/2 = {fs_hz / 2} Hz)")
        self.sos = butter(2, cutoff_hz, fs=fs_hz, output="sos")
        self._sos_rows = [tuple(float(c) for c in row) for row in self.sos]
        self.n_ch = n_ch
        self.reset()

    def reset(self) -> None:
        self.prev = None  # last (t, x) per channel
        self.zi = None

    def step(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``t`` [s] (n,), ``x`` (n, n_ch) -> filtered derivative (n, n_ch), unit of x per second."""
        n = len(t)
        if n == 0:
            return np.empty((0, self.n_ch))
        x = np.array(x, dtype=float, copy=True)
        # hold NaN: forward fill within the block (and from the previous block)
        if self.prev is None:
            t_prev, x_prev = t[0], np.where(np.isfinite(x[0]), x[0], 0.0)
        else:
            t_prev, x_prev = self.prev
        bad = ~np.isfinite(x)
        if bad.any():
            xx = np.vstack([x_prev[None, :], x])
            ok = np.isfinite(xx)
            idx = np.where(ok, np.arange(len(xx))[:, None], 0)
            idx = np.maximum.accumulate(idx, axis=0)
            xx = xx[idx, np.arange(self.n_ch)[None, :]]
            x = xx[1:]
        tt = np.concatenate([[t_prev], t])
        dt = np.diff(tt)
        dx = np.diff(np.vstack([x_prev[None, :], x]), axis=0)
        d = np.where(dt[:, None] > 0, dx / np.where(dt > 0, dt, 1.0)[:, None], 0.0)
        if self.zi is None:
            self.zi = np.repeat(sosfilt_zi(self.sos)[:, :, None], self.n_ch, axis=2) * d[0][None, None, :]
        y, self.zi = sosfilt(self.sos, d, axis=0, zi=self.zi)
        self.prev = (t[-1], x[-1].copy())
        return y

    def step_one(self, t: float, x0: float, x1: float) -> tuple[float, float]:
        """One sample of a 2-channel filter (finite inputs, state initialised by :meth:`step`).

        Same arithmetic as :meth:`step` (backward difference, then each
        second-order section in transposed direct form II, as ``sosfilt``).
        """
        t_prev, x_prev = self.prev
        dt = t - t_prev
        if dt > 0:
            d = [(x0 - x_prev[0]) / dt, (x1 - x_prev[1]) / dt]
        else:
            d = [0.0, 0.0]
        zi = self.zi
        for k, (b0, b1, b2, _, a1, a2) in enumerate(self._sos_rows):
            for ch in (0, 1):
                xin = d[ch]
                y = b0 * xin + zi[k, 0, ch]
                zi[k, 0, ch] = b1 * xin - a1 * y + zi[k, 1, ch]
                zi[k, 1, ch] = b2 * xin - a2 * y
                d[ch] = y
        x_prev[0], x_prev[1] = x0, x1
        self.prev = (t, x_prev)
        return d[0], d[1]


class PhysicsStandInExpected:
    """Physics-only stand-in for the twin (see module docstring)."""

    kind = "physics_standin"
    fallback_reason = ""  # why a configured twin is not the one running ("" when none was configured)
    edge_s = 0.0  # no derivative window to fill after a reset (its causal filter is covered by the settle interval)

    def __init__(self, params: ph.TwinParams, effects=ph.DEFAULT_EFFECTS, fs_hz: float = 1000.0,
                 accel_cutoff_hz: float = 50.0):
        self.params = params
        self.effects = list(effects)
        self.version = f"physics-standin({params.source})"
        self.fs_hz, self.accel_cutoff_hz = float(fs_hz), float(accel_cutoff_hz)
        self.deriv = CausalDerivative(2, min(accel_cutoff_hz, 0.4 * fs_hz), fs_hz)

    def reset(self) -> None:
        self.deriv.reset()

    def configure(self, fs_hz: float | None = None, N: float | None = None) -> None:
        """Input rate [Hz] now known (the derivative filter is redesigned for it: cutoff
        ``min(accel_cutoff_hz, 0.4 fs)``, then reset; nothing changes when the rate is the same).
        ``N`` is carried by the params (ignored)."""
        if fs_hz and fs_hz != self.fs_hz:
            self.fs_hz = float(fs_hz)
            self.deriv = CausalDerivative(2, min(self.accel_cutoff_hz, 0.4 * self.fs_hz), self.fs_hz)
            self.reset()

    @property
    def fs_in(self) -> float:
        """Input rate the derivative filter is designed for [Hz]."""
        return self.fs_hz

    def set_params(self, params: ph.TwinParams) -> None:
        self.params = params
        self.version = f"physics-standin({params.source})"

    def step(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        acc = self.deriv.step(t, X[:, [I_WM, I_WF]])
        temp = X[:, I_TEMP]
        temp = temp if np.isfinite(temp).all() else None
        return ph.quasi_static_Q_red(self.params, self.effects, X[:, I_TAU], X[:, I_WM], temp,
                                     theta_m_dd=acc[:, 0], theta_f_dd=acc[:, 1])

    def step_one(self, t: float, x: np.ndarray) -> float:
        """One sample (finite inputs; the segment was started by :meth:`step`): Q_red_hat [N*m]."""
        if self.deriv.prev is None:
            return float(self.step(np.array([t]), x[None, :])[0])
        a_m, a_f = self.deriv.step_one(t, float(x[I_WM]), float(x[I_WF]))
        temp = float(x[I_TEMP])
        return float(ph.quasi_static_Q_red(self.params, self.effects, float(x[I_TAU]), float(x[I_WM]),
                                           temp if temp == temp else None, theta_m_dd=a_m, theta_f_dd=a_f))


class OnnxTwinExpected:
    """The trained twin (ONNX, LSTM state carried) through ``hd_twin.runtime.StreamingTwin``."""

    kind = "onnx_twin"

    def __init__(self, model_dir: str, N: float | None = None, fs_hz: float | None = None):
        try:
            from hd_twin.runtime import StreamingTwin
        except ImportError as e:  # the twin package has no runtime in this checkout
            raise ValueError(f"{model_dir}: cannot load the streaming twin runtime ({e})") from None
        self.twin = StreamingTwin(model_dir, fs_in=fs_hz, gear_ratio=N)
        self.model_dir = str(model_dir)
        cfg = getattr(self.twin, "config", {}) or {}
        self.version = str(cfg.get("version") or cfg.get("model_version") or model_dir)
        self.N, self.fs = N, fs_hz
        self._last = np.nan
        self._fed = 0  # input rows fed since the reset
        self._ready = 0  # input rows whose Q_red_hat was given out

    @property
    def lag_samples(self) -> int:
        """Input rows between a row's arrival and its Q_red_hat (``StreamingTwin.lag_samples``; 0: causal)."""
        return int(self.twin.lag_samples)

    @property
    def delayed(self) -> bool:
        """Fixed-lag twin: :meth:`step` answers for the oldest rows not given out yet (see there)."""
        return self.twin.mode == "fixed_lag"

    def set_mode(self, mode: str) -> None:
        """``"causal"`` or ``"fixed_lag"`` (``StreamingTwin.set_mode``); resets."""
        self.twin.set_mode(mode)
        self._last, self._fed, self._ready = np.nan, 0, 0

    @property
    def fs_in(self) -> float:
        """Input rate the twin is set up for [Hz]."""
        return float(self.twin.fs_in)

    @property
    def edge_s(self) -> float:
        """Seconds after a reset whose outputs are the twin's edge samples (``StreamingTwin.edge_s``)."""
        return float(self.twin.edge_s)

    @property
    def fs_model(self) -> float:
        """Rate the twin was trained at [Hz] (its LSTM steps at this rate)."""
        return float(self.twin.fs_model)

    def configure(self, fs_hz: float | None = None, N: float | None = None) -> None:
        """Input rate [Hz] and gear ratio of the actuator now monitored (then reset).

        ValueError naming the model directory and both rates when the joint states cannot be
        decimated by an integer factor to the twin's rate (``hd_twin.data.decimation_for``): the
        caller then falls back to the physics-only stand-in; the twin keeps its previous rate.
        """
        fs_new, N_new = fs_hz or self.fs, N or self.N
        if fs_new == self.fs_in and N_new == self.N:
            return
        self.twin.reset(fs_new, N_new)  # raises before any state is changed here
        self.fs, self.N = fs_new, N_new
        self._last, self._fed, self._ready = np.nan, 0, 0

    def reset(self) -> None:
        self.twin.reset(self.fs, self.N)
        self._last, self._fed, self._ready = np.nan, 0, 0

    def step(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Q_red_hat per input sample; a decimating twin's outputs are held (zero-order) in between.

        Fixed-lag twin (:attr:`lag_samples` > 0): Q_red_hat of the oldest rows not given out yet, in order, as
        many as became known (possibly none; a row between two model samples once the earlier one is out);
        :meth:`flush` gives the rest at the end of a segment."""
        if self.twin.mode == "fixed_lag":
            self._fed += len(X)
            return self._lagged(self.twin.step(X), final=False)
        out = self.twin.step(X)
        q = np.asarray(out["Q_red"], dtype=float)
        idx = np.asarray(out.get("index", np.arange(len(q))), dtype=np.int64)
        full = np.full(len(X), np.nan)
        full[idx] = q
        ok = np.isfinite(full)
        pos = np.maximum.accumulate(np.where(ok, np.arange(len(X)), -1))
        res = np.where(pos >= 0, full[np.maximum(pos, 0)], self._last)
        if len(res):
            self._last = float(res[-1])
        return res

    def flush(self) -> np.ndarray:
        """End of a segment: Q_red_hat of the rows not given out yet (fixed-lag; causal: none)."""
        if self.twin.mode != "fixed_lag":
            return np.zeros(0)
        return self._lagged(self.twin.flush(), final=True)

    def _lagged(self, out: dict, final: bool) -> np.ndarray:
        """Rows ``_ready`` .. made known by the twin outputs ``out`` (samples since the reset, held in between)."""
        s = np.asarray(out["sample"], dtype=np.int64)
        q = np.asarray(out["Q_red"], dtype=float)
        if len(s) == 0 and not final:
            return np.zeros(0)
        d = int(self.twin.decimation)
        stop = self._fed if final else min(self._fed, int(s[-1]) + d)
        rows = np.arange(self._ready, stop)
        if len(s):  # the newest model sample at or before each row
            k = np.searchsorted(s, rows, side="right") - 1
            res = np.where(k >= 0, q[np.maximum(k, 0)], self._last)
        else:
            res = np.full(len(rows), self._last)
        self._ready = stop
        if len(res):
            self._last = float(res[-1])
        return res

    def step_one(self, t: float, x: np.ndarray) -> float:
        """One sample (the onboard short path, causal twin only): same as :meth:`step` on a one-row block."""
        q = self.twin.step(x[None, :])["Q_red"]
        if len(q) and np.isfinite(q[-1]):
            self._last = float(q[-1])
        return self._last


def make_expected(model_dir: str | None, params: ph.TwinParams, effects=ph.DEFAULT_EFFECTS,
                  fs_hz: float | None = 1000.0, log=None) -> Any:
    # the trained twin's streaming mode (causal / fixed lag) is set by the core from OnboardConfig.twin_fixed_lag
    """The ONNX twin when ``model_dir`` is given and loads, else the physics-only stand-in (logged).

    ``fs_hz`` [Hz]: the joint-state rate when known (None: not yet; the ONNX twin starts at its own
    rate, the stand-in at 1 kHz). :class:`hd_onboard.core.OnboardCore` calls ``configure(fs_hz=...)``
    once it has measured the rate and falls back to the stand-in, with a diagnostic naming both
    rates, when the twin cannot run at it. The reason of a load failure is kept in the stand-in's
    ``fallback_reason``.
    """
    reason = ""
    if model_dir:
        try:
            return OnnxTwinExpected(model_dir, N=params.N, fs_hz=fs_hz)
        except Exception as e:  # noqa: BLE001 - any load failure falls back, loudly
            reason = f"twin model {model_dir!r} not usable ({e}); using the physics-only stand-in"
            if log:
                log(reason)
    exp = PhysicsStandInExpected(params, effects, fs_hz=fs_hz or 1000.0)
    exp.fallback_reason = reason
    return exp


def finite_or(x: float, default: float) -> float:
    return float(x) if x is not None and math.isfinite(float(x)) else float(default)
