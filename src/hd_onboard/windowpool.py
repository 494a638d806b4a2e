"""Window features off the flag path: the statistics and features of the onboard core's closed windows,
computed in one worker thread (or inline) and delivered in window order (pure: no ROS).

The onboard node sets ``core.defer_windows`` and hands every closed window's job here; a flag is
never delayed by a feature computation. The worker runs ``SCHED_OTHER`` even in a process started
real-time (``hdphm node onboard --rt-priority``).
"""

from __future__ import annotations

import math
import os
import sys
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable


class WindowFeaturePool:
    """``submit`` window jobs (with their mission index), ``drain`` the finished rows in window order."""

    def __init__(self, threaded: bool = True):
        self._pool = (ThreadPoolExecutor(1, thread_name_prefix="onboard-features", initializer=_normal_priority)
                      if threaded else None)
        if self._pool is not None and sys.getswitchinterval() > 5e-4:
            # the worker holds the GIL at most this long when a sample arrives (default 5 ms)
            sys.setswitchinterval(5e-4)
        self._pending: deque = deque()  # futures of window rows, in window order

    def __len__(self) -> int:
        return len(self._pending)

    def submit(self, jobs: list, feature_fn: Callable | None, mission_index: Any, final: bool = False) -> None:
        """Queue the rows of ``jobs`` (``hd_onboard.windows.window_row``); with ``final`` the last one is marked
        as the mission's last window (column ``final`` = 1, the prognostic node commits the mission on it)."""
        from hd_onboard.windows import window_row

        mi = _float_or_nan(mission_index)
        for k, job in enumerate(jobs):
            last = final and k == len(jobs) - 1

            def work(job=job, last=last):
                row = window_row(job, feature_fn)
                if row is not None:
                    row["mission_index"] = mi
                    row["final"] = 1.0 if last else 0.0
                return row

            self._pending.append(_Done(work()) if self._pool is None else self._pool.submit(work))

    def drain(self, wait: bool = False, on_error: Callable[[Exception], None] | None = None) -> list[dict]:
        """Rows finished so far, in window order (``wait``: all of them). A failed window is passed to
        ``on_error`` and skipped: monitoring goes on."""
        rows = []
        while self._pending and (wait or self._pending[0].done()):
            try:
                r = self._pending.popleft().result()
            except Exception as e:  # noqa: BLE001 - a feature failure is reported, monitoring goes on
                if on_error is not None:
                    on_error(e)
                continue
            if r is not None:
                rows.append(r)
        return rows

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _normal_priority() -> None:
    """Worker threads (window features) run SCHED_OTHER even in a process started real-time: they must
    never delay the joint-state path."""
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        from hd_ros.context import set_thread_realtime

        set_thread_realtime(0)


class _Done:
    """A finished 'future' (no worker thread)."""

    def __init__(self, value):
        self.value = value

    def done(self) -> bool:
        return True

    def result(self):
        return self.value


def _float_or_nan(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
