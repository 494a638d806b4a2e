"""Windows: every ``window_s`` of sample time the core closes a window of residual rows.

:class:`Windows` cuts the stream (window index ``floor(t / window_s)``, ``t`` s since the mission start)
and captures a closed window's rows; :func:`window_row` turns a captured window (:class:`WindowJob`)
into the row sent to the prognostic node: residual statistics per channel (:data:`STAT_NAMES`), the
monitors' means and maxima, and, when a feature function is given, the prognostic features of
``hd_onboard.features``. With deferred windows the core only queues the jobs and the caller runs
:func:`window_row` when it chooses (the node does it in a worker thread), so closing a window never
delays the flag decision of a sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hd_onboard.buffer import RowBuffer
from hd_onboard.residuals import RESIDUAL_COLUMNS

#: residual statistics per window and channel
STAT_NAMES = ("mean", "std", "rms", "max_abs_e", "frac_warn", "n_valid")


@dataclass
class WindowJob:
    """A closed window captured for :func:`window_row` (rows copied; thresholds as they were)."""

    table: np.ndarray  # (n, len(RESIDUAL_COLUMNS))
    raw: np.ndarray  # (n, 6) samples, columns JS_COLS
    win_index: int
    window_s: float
    thresholds: dict  # channel -> ChannelThreshold
    temperature: float  # degC (NaN: unknown)


class Windows:
    """The open window of one mission: its index and rows (residual table rows and raw samples)."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self.index: int | None = None
        self._rows = RowBuffer(len(RESIDUAL_COLUMNS))
        self._raw = RowBuffer(6)
        self.emitted = 0  # windows captured this mission

    def take(self) -> tuple[np.ndarray, np.ndarray, int] | None:
        """Capture the open window: ``(table, raw, index)`` (rows copied, buffers emptied); None when empty."""
        if len(self._rows) == 0:
            self._raw.take()
            return None
        self.emitted += 1
        return self._rows.take(), self._raw.take(), int(self.index)

    def block(self, t: np.ndarray, table: np.ndarray, V: np.ndarray, close: Callable[[], Any]) -> list:
        """Add a block's rows; ``close()`` is called for each window the block closes (before the index moves
        on); its results that are not None are returned."""
        w = self.window_s
        widx = np.floor(t / w).astype(np.int64)
        out = []
        if self.index is None:
            self.index = int(widx[0])
        cut = np.flatnonzero(widx != self.index)
        start = 0
        while len(cut):
            c = int(cut[0])
            self._rows.extend(table[start:c])
            self._raw.extend(V[start:c])
            out.append(close())
            self.index = int(widx[c])
            start = c
            cut = np.flatnonzero(widx[start:] != self.index) + start
        self._rows.extend(table[start:])
        self._raw.extend(V[start:])
        return [o for o in out if o is not None]

    def one(self, t: float, row, raw, close: Callable[[], Any]):
        """Add one row (same cuts as :meth:`block`); the result of ``close()`` when the row closed a window."""
        wi = math.floor(t / self.window_s)
        w = None
        if wi != self.index:
            if self.index is None:
                self.index = wi
            else:
                w = close()
                self.index = wi
        self._rows.append(row)
        self._raw.append(raw)
        return w


def window_row(job: WindowJob, feature_fn=None, core=None) -> dict[str, Any] | None:
    """Residual statistics (and features) of one closed window: the feature row sent to the prognostic node.

    Pure: takes a :class:`WindowJob`; ``feature_fn(stamps_s, V, temperature)``
    adds ``feat.*`` entries (a failure is recorded as ``feat.error`` = NaN and,
    when ``core`` is given, its message in ``core.feature_error``).
    """
    tab, raw = job.table, job.raw
    if len(tab) == 0:
        return None
    row: dict[str, Any] = {
        "stamp_start": float(tab[0, 0]),
        "stamp_end": float(tab[-1, 0]),
        "t_start": float(job.win_index * job.window_s),
        "n": float(len(tab)),
        "max_level": float(np.max(tab[:, 7])),
    }
    for c, rcol, ecol in (("Q_red", 3, 4), ("twist", 5, 6)):
        r = tab[:, rcol]
        e = tab[:, ecol]
        ok = np.isfinite(r)
        nv = int(ok.sum())
        th = job.thresholds[c]
        if nv:
            rv = r[ok]
            row[f"{c}.mean"] = float(rv.mean())
            row[f"{c}.std"] = float(rv.std())
            row[f"{c}.rms"] = float(np.sqrt(np.mean(rv**2)))
            ev = np.abs(e[np.isfinite(e)])
            row[f"{c}.max_abs_e"] = float(ev.max()) if len(ev) else math.nan
            row[f"{c}.frac_warn"] = float((ev > th.h_warn).mean()) if len(ev) else math.nan
        else:
            for s in ("mean", "std", "rms", "max_abs_e", "frac_warn"):
                row[f"{c}.{s}"] = math.nan
        row[f"{c}.n_valid"] = float(nv)
    if tab.shape[1] > 8:  # torsional-stiffness loss (-): mean and max over the window's evaluable samples
        sl = tab[:, 8]
        sl = sl[np.isfinite(sl)]
        row["stiffness.loss"] = float(sl.mean()) if len(sl) else math.nan
        row["stiffness.max_loss"] = float(sl.max()) if len(sl) else math.nan
        row["stiffness.n_eval"] = float(len(sl))
    if tab.shape[1] > 9:  # friction excess (-): mean and max over the window's evaluable samples
        fx = tab[:, 9]
        fx = fx[np.isfinite(fx)]
        row["friction.excess"] = float(fx.mean()) if len(fx) else math.nan
        row["friction.max_excess"] = float(fx.max()) if len(fx) else math.nan
        row["friction.n_eval"] = float(len(fx))
    if feature_fn is not None:
        try:
            feats = feature_fn(tab[:, 0], raw, job.temperature)
            row.update({f"feat.{k}": float(v) for k, v in feats.items()})
        except Exception as e:  # noqa: BLE001 - a feature failure must not stop monitoring
            row["feat.error"] = math.nan
            if core is not None:
                core.feature_error = f"{type(e).__name__}: {e}"
    return row
