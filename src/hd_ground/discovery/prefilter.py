"""The pre-sliding distance identified on the equation filtered as the acceleration is (issue 10, eleventh pass).

The motor acceleration discovery works with is a smoothed derivative of the logged speed
(:func:`hd_twin.speedtiming.sg2_derivative`, window ``Dataset.alpha_window``). A centred derivative filter
``sum_k c_k omega[n + k] / dt`` is, by summation by parts, a weighted mean of the true acceleration over the
sample intervals inside its window (weights ``-cumsum(c)``); on the sample grid that is the smoothing kernel
``K = (-cumsum(c)) * [1/2, 1/2]`` (:func:`implied_kernel`). So ``alpha_m = K * alpha_true`` up to the
sampling, and the torque balance holds exactly only in the filtered domain:

    K * tau_m = J_eq alpha_m + K * (Q_red / N) + T_C K * s(theta_m; d) + b K * omega_m  (+ ...)

On the raw columns the inertia torque's error J (alpha_true - K * alpha_true) is where the true acceleration
changes fast: at hard reversals, which is where the friction state switches; a longer transition then takes
part of it up and the profile of d is biased (docs/DISCOVERY_PASSES.md, ninth pass: 1.3-2.2x the truth at
seed 1300). Filtering every non-derivative column and the target with ``K`` (the acquisition model of the
differentiator, the state-variable-filter idea of continuous-time identification) removes that error from
the equation the nonlinear parameter is profiled on.

In the filtered equation the state's timing against the logged torque is resolved as well (the torque is
logged as a mean over the logging period, the angle as a sample): the state is evaluated at ``theta_m`` a
fraction ``shift`` of a sample later (linear interpolation), and (d, shift) are profiled jointly by the same
CV profile + block jackknife as every shape. The baseline then uses the state at that (d, shift) on the raw
columns; its law is still chosen against tanh by the raw CV error (the selection's own rule).
"""

from __future__ import annotations

import numpy as np

from hd_twin.speedtiming import _window

#: Signals that are themselves smoothed derivatives (already carry the derivative filter): not filtered again.
DERIVATIVE_SIGNALS = ("alpha_m", "alpha_m_dot", "alpha_f")
#: Searched range of the state's timing, in samples (the torque's averaging period is one sample).
SHIFT_RANGE = (-1.0, 1.0)


def implied_kernel(window: int) -> np.ndarray:
    """Smoothing kernel (length ``window``, sums to 1) on the sample grid that the centred quadratic
    Savitzky-Golay derivative of ``window`` samples applies to the true derivative (central differences
    below 5 samples, as :func:`hd_twin.speedtiming.sg2_derivative`)."""
    if window < 5:
        c = np.array([-0.5, 0.0, 0.5])
    else:
        m = window // 2
        k = np.arange(-m, m + 1, dtype=float)
        c = k / np.sum(k**2)
    w = -np.cumsum(c)[:-1]  # weights of the sample intervals' mean derivative
    return np.convolve(w, [0.5, 0.5])


def smooth_like_derivative(X: np.ndarray, t: np.ndarray, segment: np.ndarray, window_s: float) -> np.ndarray:
    """``X`` (n,) or (n, p) filtered per segment with :func:`implied_kernel` of the derivative window ``window_s``
    (the window in samples as the derivative computes it; ends padded with the edge value)."""
    X = np.asarray(X, float)
    out = np.array(X, copy=True)
    for s in np.unique(segment):
        idx = np.flatnonzero(segment == s)
        if len(idx) < 3:
            continue
        dt = float(np.median(np.diff(t[idx])))
        if not dt > 0:
            continue
        K = implied_kernel(_window(dt, window_s))
        h = len(K) // 2
        if len(idx) <= len(K):
            continue
        pad = [(h, h)] + [(0, 0)] * (X.ndim - 1)
        Xs = np.pad(X[idx], pad, mode="edge")
        if X.ndim == 1:
            out[idx] = np.convolve(Xs, K, "valid")
        else:
            out[idx] = np.stack([np.convolve(Xs[:, j], K, "valid") for j in range(X.shape[1])], 1)
    return out


def shift_samples(x: np.ndarray, shift: float, segment: np.ndarray) -> np.ndarray:
    """``x`` a fraction ``shift`` of a sample later (linear interpolation within each segment; ends held)."""
    x = np.asarray(x, float)
    if shift == 0.0:
        return x
    out = np.empty_like(x)
    for s in np.unique(segment):
        idx = np.flatnonzero(segment == s)
        i = np.arange(len(idx), dtype=float)
        out[idx] = np.interp(i + shift, i, x[idx])
    return out


def filtered_design(matrix_full, derivative_cols: list[bool], t_full: np.ndarray, segment_full: np.ndarray,
                    window_s: float, rows: np.ndarray):
    """``design(shape) -> filtered columns at rows``: ``matrix_full(shape)`` (the columns on the full, time-ordered
    series) with every column not in ``derivative_cols`` filtered by :func:`smooth_like_derivative`."""
    keep = np.asarray(derivative_cols, bool)

    def design(sh):
        M = matrix_full(sh)
        Ms = smooth_like_derivative(M, t_full, segment_full, window_s)
        Ms[:, keep] = M[:, keep]
        return Ms[rows]
    return design


def shifted_state_var(var: str, distance: float, shift: float) -> str:
    """Column name of the pre-sliding state of ``var`` a fraction ``shift`` of a sample later (``state_var`` when
    the shift is 0); ``core.StateSignals`` computes it."""
    from .library import STATE_PREFIX, state_var

    if shift == 0.0:
        return state_var(var, distance)
    return f"{STATE_PREFIX}{var}:{float(distance)!r}:{float(shift)!r}"
