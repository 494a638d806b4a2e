"""Streaming derivative filters of the twin as fixed FIR weights, designed once per rate.

The batch twin differentiates a whole segment with a Savitzky-Golay filter (``mode="interp"``): the
centre row of weights inside the segment, the fit of the first / last window evaluated at the edge
positions within half a window of either end, and central differences (``np.gradient``) when the
segment is not longer than the window. Those weights depend only on (window, polynomial order, sample
period), so the streaming twin takes them once per rate and applies them by dot products on the last
samples it keeps; nothing is re-designed or re-fitted per call.

Two streaming evaluations of the same weights:

* :class:`CausalSGHistory` (``mode="causal"`` of :class:`hd_twin.runtime.StreamingTwin`, the
  behaviour of every earlier runtime, output for output): each call's newest samples get the
  end-of-window rows (one-sided, past samples only), the older samples of the call the centre row;
  no delay, the result depends on how the stream is cut into calls.
* :class:`CentredFIR` (``mode="fixed_lag"``): the derivative of sample k is emitted when sample
  k + m arrives (m = w // 2, the half window), with exactly the batch rule (centre row; left-edge rows
  for the first m samples once w + 1 samples are in; right-edge rows for the last m at :meth:`flush`,
  the end of the segment; central differences for a segment not longer than the window), so it equals
  the batch derivative sample for sample whatever the calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FIRWeights:
    """First-derivative weights of one filter: ``centre`` (w,), ``left`` / ``right`` (m, w), m = w // 2.

    ``left[k] @ x[:w]`` is the derivative at sample k < m of a segment, ``right[j] @ x[-w:]`` the one at
    sample n - m + j, ``centre @ x[k - m:k + m + 1]`` the one at any other sample."""

    centre: np.ndarray
    left: np.ndarray
    right: np.ndarray
    dt: float

    @property
    def w(self) -> int:
        return len(self.centre)

    @property
    def m(self) -> int:
        return len(self.centre) // 2


def sg_weights(w: int, polyorder: int, dt: float) -> FIRWeights:
    """Savitzky-Golay first-derivative weights (the cached rows :func:`hd_twin.identify._sg_coefficients`
    that the batch derivative :func:`hd_twin.identify.derivative` applies)."""
    from .identify import _sg_coefficients  # noqa: PLC0415

    c, lft, rgt = _sg_coefficients(int(w), int(polyorder), f"{float(dt):.12g}")
    return FIRWeights(c, lft, rgt, float(dt))


def gradient_weights(dt: float) -> FIRWeights:
    """``np.gradient`` (uniform spacing, first-order edges) as a 3-sample FIR."""
    dt = float(dt)
    return FIRWeights(np.array([-0.5, 0.0, 0.5]) / dt, np.array([[-1.0, 1.0, 0.0]]) / dt,
                      np.array([[0.0, -1.0, 1.0]]) / dt, dt)


def _centre_rows(x: np.ndarray, centre: np.ndarray, start: int, stop: int) -> np.ndarray:
    """``centre @ x[k - m:k + m + 1]`` for k in [start, stop) (x 1-D or (n, c))."""
    m = len(centre) // 2
    if stop <= start:
        return np.zeros((0,) + x.shape[1:])
    win = np.lib.stride_tricks.sliding_window_view(x[start - m:stop + m], len(centre), axis=0)
    return win @ centre


class CausalSGHistory:
    """The causal streaming derivative of the earlier runtime, with fixed weights.

    The earlier runtime ran :func:`hd_twin.identify.derivative` on the samples since the reset (at most
    ``2 w + 2`` of them before the new ones) at every call and kept the new samples' values: fewer than 3
    samples in that history: 0; not more than w: central differences over it; more: Savitzky-Golay with
    the end-of-window rows for the newest m samples. This class keeps the last ``w`` samples and
    evaluates only the new samples' rows, which gives the same numbers (to float rounding) at O(w) per
    sample.
    """

    def __init__(self, weights: FIRWeights):
        self.wt = weights
        self.reset()

    def reset(self) -> None:
        self.hist = np.zeros(0)
        self.n = 0  # samples since the reset

    def step(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        b = len(x)
        if b == 0:
            return np.zeros(0)
        wt = self.wt
        w, m = wt.w, wt.m
        if b == 1 and self.n >= w:  # the steady one-sample call: the last end-of-window row, one dot product
            H = np.concatenate([self.hist[1:], x])
            self.hist = H
            self.n += 1
            return np.array([wt.right[-1] @ H])
        H = np.concatenate([self.hist, x]) if len(self.hist) else x
        L = len(H)
        first = L - b  # position of the first new sample in H
        if L < 3:
            out = np.zeros(b)
        elif L <= w:
            out = np.gradient(H, wt.dt)[first:]
        else:
            out = np.empty(b)
            p = np.arange(first, L)
            lo = p < m  # only right after a reset: the fit of the first window
            if lo.any():
                out[lo] = wt.left[p[lo]] @ H[:w]
            hi = p >= L - m
            if hi.any():
                out[hi] = wt.right[p[hi] - (L - m)] @ H[-w:]
            mid = ~lo & ~hi
            if mid.any():
                a, z = int(p[mid][0]), int(p[mid][-1]) + 1
                out[mid] = _centre_rows(H, wt.centre, a, z)
        self.n += b
        # what the next call's rows can reach: w samples (so a one-sample call still sees more than w), all
        # of them while fewer came in (the left-edge rows fit the first window after the reset)
        self.hist = H[-w:] if self.n >= w else H
        return out


class CentredFIR:
    """Fixed-lag centred derivative equal to the batch one (see the module docstring).

    :meth:`push` takes new samples (1-D, or (n, c) for c signals at once) and returns the derivatives
    that became known (oldest first; sample indices ``emitted - len(out)`` .. ``emitted - 1`` since the
    reset); :meth:`flush` returns the rest at the end of a segment. ``short(x)``: the batch rule for a
    segment of ``len(x) <= w`` samples (default ``np.gradient``, NaN for fewer than 3 samples).
    """

    def __init__(self, weights: FIRWeights, short=None):
        self.wt = weights
        self.short = short or self._gradient
        self.reset()

    def _gradient(self, x: np.ndarray) -> np.ndarray:
        if len(x) < 3:
            return np.full(x.shape, np.nan)
        return np.gradient(x, self.wt.dt, axis=0)

    @property
    def lag(self) -> int:
        """Samples between a sample's arrival and its derivative (after the first window)."""
        return self.wt.m

    def reset(self) -> None:
        self.buf = None  # samples from absolute index self.s0 on
        self.s0 = 0
        self.n = 0  # samples since the reset
        self.emitted = 0  # derivatives given out since the reset

    def push(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        w, m = self.wt.w, self.wt.m
        if len(x) == 1 and self.emitted == self.n - m > 0:  # the steady one-sample call: one centre-row dot product
            B = np.concatenate([self.buf[1:], x]) if len(self.buf) >= w else np.concatenate([self.buf, x])
            self.s0 += len(self.buf) + 1 - len(B)
            self.buf = B
            self.n += 1
            self.emitted += 1
            return (self.wt.centre @ B[-w:])[None]
        self.buf = x.copy() if self.buf is None else np.concatenate([self.buf, x])
        self.n += len(x)
        if self.n <= w:  # batch differentiates a segment of <= w samples otherwise: wait for the next sample
            return np.zeros((0,) + x.shape[1:])
        stop = self.n - m  # samples k < stop have their window
        out = self._rows(self.emitted, stop, edge_right=False)
        self.emitted = stop
        keep_from = max(0, min(self.emitted - m, self.n - w))
        if keep_from > self.s0:
            self.buf = self.buf[keep_from - self.s0:]
            self.s0 = keep_from
        return out

    def flush(self) -> np.ndarray:
        """The derivatives not given out yet (the segment's last m samples: right-edge rows; a segment of
        <= w samples: ``short`` over all of it). The filter is then empty (call :meth:`reset` before reuse)."""
        if self.buf is None or self.n == self.emitted:
            return np.zeros((0,) + (() if self.buf is None else self.buf.shape[1:]))
        if self.n <= self.wt.w:
            out = self.short(self.buf)
        else:
            out = self._rows(self.emitted, self.n, edge_right=True)
        self.emitted = self.n
        return out

    def _rows(self, a: int, b: int, edge_right: bool) -> np.ndarray:
        w, m = self.wt.w, self.wt.m
        B, s0 = self.buf, self.s0
        parts = []
        k = a
        if k < m and k < b:  # left-edge rows over the first window
            z = min(m, b)
            parts.append(np.tensordot(self.wt.left[k:z], B[:w], axes=(1, 0)))
            k = z
        z = min(b, self.n - m)
        if z > k:
            parts.append(_centre_rows(B, self.wt.centre, k - s0, z - s0))
            k = z
        if edge_right and b > k:
            parts.append(np.tensordot(self.wt.right[k - (self.n - m):b - (self.n - m)], B[-w:], axes=(1, 0)))
        if not parts:
            return np.zeros((0,) + B.shape[1:])
        return np.concatenate(parts) if len(parts) > 1 else parts[0]
