"""When the onboard node publishes what (pure: no ROS; the node asks, then publishes).

:class:`PublishSchedule` holds the published state and decides, after each processed block or
sample:

* ``/diagnostics`` (the full onboard report, :mod:`hd_onboard.status`): on every level change and
  every ``diag_period_s`` of *sample* time; not while no actuator is named yet (neither
  ``/hd/mission`` nor a ``frame_id``) and the node is younger than ``stale_timeout_s`` of wall time
  (no status under "unknown" that a mission would rename a moment later);
* ``/hd/onboard/residuals``: rows batched, one message per ``residual_rows`` rows, sooner on a level
  change or when forced (a short-path sample that changed the level: the flag goes out first);
* the STALE watchdog (wall clock, a timer): joint states silent for more than ``stale_timeout_s``
  -> STALE reports on every tick, and the mission's last window closed once on entering.

:class:`InputBook` keeps the per-topic input counts of those reports. :func:`window_table` is the
``/hd/onboard/features`` table of finished window rows.
"""

from __future__ import annotations

import math

import numpy as np

from hd_onboard.detectors.levels import OK


class PublishSchedule:
    def __init__(self, diag_period_s: float, residual_rows: int, stale_timeout_s: float, t_start: float):
        self.diag_period_s = float(diag_period_s)  # s of sample time between periodic reports
        self.residual_rows = int(residual_rows)  # rows per residual message
        self.stale_timeout_s = float(stale_timeout_s)  # s of wall time
        self.t_start = t_start  # wall (monotonic) time the node started
        self.level = OK  # the level last published
        self.last_diag_t = -math.inf  # sample time [s] of the last report
        self.stale = False  # joint states currently STALE (watchdog)

    def reset(self) -> None:
        """A new core: its first block reports at once, from level OK."""
        self.last_diag_t = -math.inf
        self.level = OK

    def after_samples(self, level: int, last_ns: int | None, n_rows: int, force_rows: bool = False) -> tuple[bool, bool]:
        """The core is at ``level`` with sample time ``last_ns`` and ``n_rows`` pending rows: (publish the
        report, publish the rows). A report due takes ``level`` as the published one."""
        t_now = last_ns * 1e-9 if last_ns is not None else 0.0
        changed = level != self.level
        report = changed or t_now - self.last_diag_t >= self.diag_period_s
        if report:
            self.level = level
            self.last_diag_t = t_now
        return report, changed or force_rows or n_rows >= self.residual_rows

    def may_report(self, hardware_id: str, now: float) -> bool:
        """A report may go out: the actuator is named, or the node has waited ``stale_timeout_s`` for a name."""
        return bool(hardware_id) or now - self.t_start >= self.stale_timeout_s

    def watchdog(self, last_wall: float | None, now: float) -> tuple[bool, bool]:
        """A timer tick at wall time ``now``, joint states last taken at ``last_wall``: (close the mission's
        windows now: STALE just began, publish a STALE report: joint states are STALE)."""
        if last_wall is not None and now - last_wall > self.stale_timeout_s:
            entered = not self.stale
            self.stale = True
            return entered, True
        self.stale = False
        return False, False


class InputBook:
    """Per contract topic: messages taken, decoded, wall time of the last take, stamp [ns] of the last
    sample; undecodable joint states (the first :attr:`MAX_REPORTED` are reported one by one)."""

    MAX_REPORTED = 3

    def __init__(self, topics):
        self.n_msgs = {t: 0 for t in topics}  # decoded messages
        self.n_taken = {t: 0 for t in topics}  # messages taken from DDS (decodable or not)
        self.last_wall = {t: None for t in topics}
        self.last_stamp = {t: None for t in topics}
        self.n_bad = 0

    def bad(self) -> bool:
        """One more undecodable message: whether to report it."""
        self.n_bad += 1
        return self.n_bad <= self.MAX_REPORTED


def window_table(rows: list[dict]) -> tuple[list[str], np.ndarray]:
    """Finished window rows (dicts, in window order) as one table: sorted union of keys, NaN where absent."""
    keys = sorted({k for w in rows for k in w})
    return keys, np.array([[float(w.get(k, math.nan)) for k in keys] for w in rows])
