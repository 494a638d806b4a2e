"""Growable float64 row buffer: what the core accumulates (warm-up samples, an open window, residual rows)."""

from __future__ import annotations

import numpy as np


class RowBuffer:
    """Growable row buffer (float64, ``k`` columns): cheap single-row appends, block extends."""

    __slots__ = ("a", "n")

    def __init__(self, k: int | None, cap: int = 2048):
        self.a = np.empty((cap,) if k is None else (cap, k))
        self.n = 0

    def _grow(self, need: int) -> None:
        cap = len(self.a)
        while cap < need:
            cap *= 2
        b = np.empty((cap,) + self.a.shape[1:])
        b[:self.n] = self.a[:self.n]
        self.a = b

    def append(self, row) -> None:
        if self.n >= len(self.a):
            self._grow(self.n + 1)
        self.a[self.n] = row
        self.n += 1

    def extend(self, rows: np.ndarray) -> None:
        m = len(rows)
        if self.n + m > len(self.a):
            self._grow(self.n + m)
        self.a[self.n:self.n + m] = rows
        self.n += m

    def take(self) -> np.ndarray:
        """Copy of the rows, then empty."""
        out = self.a[:self.n].copy()
        self.n = 0
        return out

    def __len__(self) -> int:
        return self.n
