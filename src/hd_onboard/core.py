"""The onboard (real-time) core: conditioning -> expected response -> residuals -> flags -> windows.

Pure numpy, streaming, one actuator: the onboard node feeds it the blocks of
samples it takes from its subscriptions, :func:`hd_onboard.batch.run_mission`
feeds it a whole :class:`hd_bag.mission.Mission` in blocks (batch, tests,
benchmarks, the ground's threshold calibration): both produce the same numbers.

:class:`OnboardCore` is the orchestration only; each step is its own concept:

* :mod:`hd_onboard.guard`: input guard (stamp order, rate, gaps, NaN, input problems);
* :mod:`hd_onboard.residuals`: expected response (the twin, its fallbacks) and residual channels;
* :mod:`hd_onboard.warmup`: twist zero, monitor references and self-calibrated lines of the warm-up;
* :mod:`hd_onboard.detection`: EWMA detectors, stiffness / friction monitors, the held level, events
  (the detectors themselves in :mod:`hd_onboard.detectors`);
* :mod:`hd_onboard.windows`: windows of ``window_s`` and their statistics / features row;
* :mod:`hd_onboard.config`: the parameters (:class:`OnboardConfig`, every field a node parameter).

Two entry points give the same numbers (tested to 1e-9):

* :meth:`OnboardCore.push` takes a block (vectorised; batch, replay at max rate);
* :meth:`OnboardCore.push_one` takes one sample (the real-time short path:
  scalar arithmetic, no temporary arrays, about 20x cheaper than a
  one-row block). Anything unusual for that sample (rate not yet known, NaN,
  a gap, the end of the warm-up) is handed to :meth:`push`.

With ``defer_windows = True`` a closed window is only captured (a copy of
its rows); its statistics and features, the costly part, are computed by
:func:`hd_onboard.windows.window_row` when the caller chooses (the node does it
in a worker thread), so closing a window never delays the flag decision of a sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hd_onboard.buffer import RowBuffer
from hd_onboard.config import OnboardConfig
from hd_onboard.detection import Detection
from hd_onboard.detectors.ewma import ChannelThreshold
from hd_onboard.detectors.friction import FrictionReference
from hd_onboard.detectors.stiffness import StiffnessReference
from hd_onboard.guard import InputGuard
from hd_onboard.residuals import RESIDUAL_COLUMNS, BlockResiduals, Residuals
from hd_onboard.warmup import WarmUp
from hd_onboard.windows import WindowJob, Windows, window_row
from hd_twin import physics as ph


@dataclass
class PushResult:
    table: np.ndarray  # (n, len(RESIDUAL_COLUMNS)), rows of accepted samples
    level: int  # level after the block
    events: list[tuple[int, int, str]] = field(default_factory=list)  # (stamp_ns, new level, reason) on rises
    windows: list[dict[str, Any]] = field(default_factory=list)


class OnboardCore:
    """Streaming residual / threshold / flag core for one actuator (see module docstring)."""

    def __init__(self, expected=None, params: ph.TwinParams | None = None, gear_ratio: float | None = None,
                 thresholds: dict[str, ChannelThreshold] | None = None, config: OnboardConfig | None = None,
                 feature_fn=None):
        self.cfg = (config or OnboardConfig()).validate()
        params = (params or ph.TwinParams.from_yaml())
        if gear_ratio is not None:
            params = params.with_meta(gear_ratio=gear_ratio)
        self.residuals = Residuals(expected, params, self.cfg)
        self.detection = Detection(self.cfg, thresholds)
        self.feature_fn = feature_fn
        self.defer_windows = False  # True: closed windows wait in window_jobs for window_row()
        self.window_jobs: list[WindowJob] = []
        self.reset_mission()

    # ---- configuration -----------------------------------------------------
    def set_thresholds(self, thresholds: dict[str, ChannelThreshold]) -> None:
        """New per-channel thresholds (ground adaptation); the EWMA state is kept."""
        self.detection.set_thresholds(thresholds)

    def set_params(self, params: ph.TwinParams) -> None:
        self.residuals.set_params(params)

    def set_stiffness_reference(self, ref: StiffnessReference | dict | None) -> None:
        """Healthy torsion law given by the ground (None: learn it on each mission's warm-up again).

        A ground reference wins over the warm-up's: it is applied at once (the monitor's moments
        restart: a twin update arriving mid-mission) and at every mission start, where the monitor
        then runs from the first sample instead of after the warm-up, so a stiffness loss already
        present at mission start is measured against the healthy law (the warm-up would learn the
        damaged one). The offset ``a`` is the ground's; the monitor's regression has its own
        intercept, so per-mission encoder offsets do not bias the compliance ratio. A dict is
        validated (:meth:`StiffnessReference.from_dict`); None takes effect at the next mission.
        """
        self.detection.set_stiffness_reference(ref)

    def set_friction_reference(self, ref: FrictionReference | dict | None) -> None:
        """Healthy friction mismatch given by the ground (None: learn it on each mission's warm-up again).

        Same rules as :meth:`set_stiffness_reference`: applied at once (moments restart) and at every
        mission start, monitoring from the first sample. The reference must have been fitted on residuals
        of the same twin (parameters and model) as this core's: the ground fits it with the parameters it
        pushes in the same update. A dict is validated (:meth:`FrictionReference.from_dict`).
        """
        self.detection.set_friction_reference(ref)

    # ---- state seen from outside -------------------------------------------------
    params = property(lambda self: self.residuals.params, doc="twin parameters (SI)")
    expected = property(lambda self: self.residuals.expected, doc="the expected-response model running now")
    expected_configured = property(lambda self: self.residuals.expected_configured,
                                   doc="the expected-response model configured (each mission starts on it)")
    temperature = property(lambda self: self.residuals.temperature, doc="last temperature sample [degC]")
    theta_ref = property(lambda self: self.residuals.theta_ref, doc="last command [rad]")
    fs = property(lambda self: self.guard.fs, doc="joint-state rate [Hz] (None: not known yet)")
    last_ns = property(lambda self: self.guard.last_ns, doc="last accepted stamp [ns]")
    health = property(lambda self: self.guard.health, doc="conditioning counts of this mission (InputHealth)")
    input_notes = property(lambda self: self.guard.notes,
                           doc="input problems of this mission: key -> (level, message); see input_status")
    level = property(lambda self: self.detection.level, doc="fault level after the last sample")
    onset_ns = property(lambda self: self.detection.onset_ns, doc="stamp of the first rise this mission")
    calibrated = property(lambda self: self.detection.calibrated, doc="lines known for every channel")
    detectors = property(lambda self: self.detection.detectors, doc="channel -> ChannelDetector")
    stiffness = property(lambda self: self.detection.stiffness, doc="the StiffnessMonitor")
    friction = property(lambda self: self.detection.friction, doc="the FrictionMonitor")
    windows_emitted = property(lambda self: self.win.emitted, doc="windows captured this mission")

    @property
    def thresholds(self) -> dict[str, ChannelThreshold]:
        return self.detection.thresholds

    @property
    def fallback_reason(self) -> str:
        """Why the configured twin is not the one running ("" when it is)."""
        return self.residuals.fallback_reason

    def stiffness_status(self) -> dict[str, Any]:
        """State of the stiffness monitor for ``/diagnostics`` (``hdphm/onboard/stiffness``).

        ``level`` (OK/WARN/ERROR, persistence applied), ``loss`` (last evaluable stiffness loss
        1 - 1/s, -), ``compliance_ratio`` s, ``loss_warn``/``loss_error``, ``n_eval`` (evaluable
        samples this mission), ``reference`` (source, or "learning" during the warm-up, or
        "none" when the warm-up defined no torsion law: too little load variation), the
        reference's secant ``compliance`` [rad/(N*m)] and load range ``q_range`` [N*m].
        """
        return self.detection.stiffness_status(not self.warmup.done)

    def friction_status(self) -> dict[str, Any]:
        """State of the friction (lubrication) monitor for ``/diagnostics`` (``hdphm/onboard/friction``).

        ``level`` (OK/WARN/ERROR, persistence applied), ``excess`` (last evaluable friction excess, -,
        extra output-referred friction torque / ``scale``), ``excess_warn``/``excess_error``, ``n_eval``,
        ``reference`` (source, "learning" during the warm-up, or "none": no measured Q_red or no motion in
        both directions in the warm-up), the reference's ``b`` [N*m] and ``scale`` [N*m].
        """
        return self.detection.friction_status(not self.warmup.done)

    def take_input_notes(self) -> list[tuple[str, int, str]]:
        """Input problems recorded since the last call: ``(key, level, message)``, oldest first."""
        return self.guard.take_notes()

    def input_status(self) -> tuple[int, str]:
        """Worst input problem of this mission for ``/diagnostics``: ``(level, message)`` (OK, "ok" when none).

        Keys of :attr:`input_notes`: ``twin_rate`` (ERROR: the configured twin cannot run at the
        joint-state rate; physics-only stand-in used), ``twist_reference`` (WARN: theta_m and theta_f
        without a common zero; twist channels relative to the warm-up zero, twin replaced by the
        stand-in), ``speed_scale`` / ``torque_sign`` (WARN: unit or sign errors seen over the warm-up),
        ``short`` (WARN: the mission ended before the warm-up did: nothing evaluated).
        """
        return self.guard.status()

    # ---- mission -------------------------------------------------------------
    def reset_mission(self) -> None:
        """Forget everything of the current mission (a new mission starts)."""
        cfg = self.cfg
        self.guard = InputGuard(cfg)
        self.residuals.new_mission()
        self.detection.new_mission(self.guard.fs)
        self.warmup = WarmUp(cfg)
        self.win = Windows(cfg.window_s)
        self.window_jobs = []
        self.rows = RowBuffer(len(RESIDUAL_COLUMNS), 256)  # push_one's residual rows (take_rows)
        self.events: list[tuple[int, int, str]] = []  # push_one's rising edges (take_events)
        self.windows: list[dict[str, Any]] = []  # push_one's closed windows (take_windows)
        if self.guard.fs is not None:
            self.residuals.rate_known(self.guard.fs, None, self.guard.note)

    def end_mission(self) -> None:
        """End of the mission (batch / a new /hd/mission): the rows a fixed-lag twin still holds (:meth:`drain`,
        into :meth:`take_rows` / :meth:`take_events` / :meth:`take_windows`); notes what could not be evaluated."""
        r = self.drain()
        for row in r.table:
            self.rows.append(row)
        self.events.extend(r.events)
        self.windows.extend(r.windows)
        self.guard.end_mission(self.warmup.done)

    def push_temperature(self, stamp_ns: int, value: float) -> None:
        """A temperature sample [degC] (the gearbox frame is preferred by the caller)."""
        if math.isfinite(value) and -100.0 < value < 400.0:
            self.residuals.temperature = float(value)

    def push_command(self, stamp_ns: int, theta_ref: float) -> None:
        self.residuals.theta_ref = float(theta_ref)

    # ---- the block path ------------------------------------------------------
    def push(self, stamps_ns: np.ndarray, V: np.ndarray) -> PushResult:
        """Process a block of joint-state samples.

        ``stamps_ns`` int64 (n,), ``V`` float (n, 6) with columns :data:`hd_onboard.residuals.JS_COLS`
        (SI). Returns the residual table of the accepted samples, the level
        after the block, rising-edge events and the windows closed by the block.
        """
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        V = np.asarray(V, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 6 or len(V) != len(stamps_ns):
            raise ValueError(f"onboard core: expected stamps (n,) and samples (n, 6), got {stamps_ns.shape} and {V.shape}")
        g = self.guard
        stamps_ns, V = g.order(stamps_ns, V)  # 1. stamp order
        if len(stamps_ns) == 0:
            return PushResult(np.empty((0, len(RESIDUAL_COLUMNS))), self.level)
        V = g.unwrap(stamps_ns, V)  # an angle arriving within one turn, unwrapped with its speed
        if g.start(stamps_ns):  # the rate became known
            self.detection.configure_rates(g.fs)
            self.residuals.rate_known(g.fs, (int(stamps_ns[0]) - g.t0_ns) * 1e-9, g.note)
        if not g.twist_checked:
            msg = g.check_twist_reference(V, self.params.N)
            if msg is not None:
                self.residuals.twist_reference_problem(g.fs, msg, g.note)
        c = g.condition(stamps_ns, V)  # 2. gaps, NaN, held twin inputs
        r = self.residuals.block(c.t, V, c.Vh, c.valid, c.reset_at, stamps_ns)  # 3. expected response, residuals
        g.health.n_resets += r.n_resets
        g.last_ns = int(stamps_ns[-1])
        if r.t is None:  # the block's own rows (no fixed-lag twin)
            r = r._replace(t=c.t, stamps=stamps_ns, V=V)
        return self._after_residuals(r)

    def _after_residuals(self, r: BlockResiduals) -> PushResult:
        """Warm-up, detection, table and windows of the rows the residuals ``r`` belong to (``r.t``, ``r.stamps``,
        ``r.V``: a fixed-lag twin's rows come ``lag_samples`` late)."""
        t, stamps_ns, V = r.t, r.stamps, r.V
        if len(t) == 0:
            return PushResult(np.empty((0, len(RESIDUAL_COLUMNS))), self.level)
        r_tw = self._warmup_block(t, V, r)  # 4. warm-up: twist zero, references, self-calibration
        es, lev, stiff, fric, events = self.detection.block(  # 5. detectors, monitors, level
            t, stamps_ns, r.r_Q, r_tw, r.twist_raw, r.Q_for_twist, V[:, 2], r.evaluate)
        table = np.column_stack([stamps_ns * 1e-9, r.Q_meas, r.Q_hat, r.r_Q, es["Q_red"], r_tw, es["twist"],
                                 lev.astype(float), stiff, fric])
        windows = self.win.block(t, table, V, self._close_window)  # 6. windows
        return PushResult(table, self.level, events, windows)

    def drain(self) -> PushResult:
        """End of the mission with a fixed-lag twin: the rows it still holds (the segment's last ``lag_samples``,
        not evaluated: the batch twin's edge samples) go through warm-up, detection and windows; empty otherwise.
        :meth:`end_mission` calls it (its rows, events and windows then wait in :meth:`take_rows` etc.)."""
        r = self.residuals.drain()
        if r is None:
            return PushResult(np.empty((0, len(RESIDUAL_COLUMNS))), self.level)
        return self._after_residuals(r)

    def _warmup_block(self, t: np.ndarray, V: np.ndarray, r: BlockResiduals) -> np.ndarray:
        """Warm-up collection and, at its end, what it taught; the twist channel relative to its zero."""
        wu, det, cfg = self.warmup, self.detection, self.cfg
        if wu.twist_zero is None and wu.block(t, V, r.twist_raw, r.Q_for_twist, r.r_Q, r.twist, self.params,
                                              det.given_stiffness is not None, det.given_friction is not None):
            det.learnt_references(wu.stiffness_ref, wu.friction_ref)
            self.guard.check_units(wu.take_raw(), self.params.N)
        if wu.twist_zero is not None:
            r_tw = np.where(t < cfg.warmup_s, np.nan, r.twist - wu.twist_zero)
        else:
            r_tw = np.full(len(t), np.nan)
        if not det.calibrated:  # self-calibration when the ground has not given thresholds
            lines = wu.self_calibrate(t, {"Q_red": r.r_Q, "twist": r.twist}, self.guard.fs or 1000.0,
                                      self.params.K_out, det.given_thresholds)
            if lines is not None:
                det.apply_calibration(lines)
        return r_tw

    # ---- windows -------------------------------------------------------------
    def _close_window(self) -> dict[str, Any] | None:
        """Capture the open window; its row now (None if deferred or empty)."""
        w = self.win.take()
        if w is None:
            return None
        job = WindowJob(w[0], w[1], w[2], self.cfg.window_s, self.detection.thresholds, self.residuals.temperature)
        if self.defer_windows:
            self.window_jobs.append(job)
            return None
        return window_row(job, self.feature_fn, self)

    def take_window_jobs(self) -> list[WindowJob]:
        """Closed windows waiting for :func:`window_row` (deferred mode), oldest first; the list is emptied."""
        jobs, self.window_jobs = self.window_jobs, []
        return jobs

    def flush(self) -> list[dict[str, Any]]:
        """Close the open window (end of mission). Deferred mode: returns [] and queues the job."""
        r = self._close_window()
        return [r] if r is not None else []

    # ---- the real-time short path -------------------------------------------
    def push_one(self, stamp_ns: int, v) -> int:
        """Process one joint-state sample; returns the level after it.

        ``v``: the 6 values of :data:`hd_onboard.residuals.JS_COLS` (SI, a sequence of floats).
        Same arithmetic as :meth:`push` on a one-row block, in scalars. The
        residual row is appended to :attr:`rows` (take them with
        :meth:`take_rows`); rising edges go to :attr:`events`; closed
        windows are returned by :meth:`take_windows` (or queued as jobs in
        deferred mode).
        """
        g, wu, det, res = self.guard, self.warmup, self.detection, self.residuals
        fs = g.fs
        last = g.last_ns
        tm, tf, wm, wf, tau, Q = v
        # the cases the short path does not handle go through the block path
        cfg = self.cfg
        if (fs is None or last is None or stamp_ns <= last or g.nan_run or not g.twist_checked
                or not math.isfinite(tm + tf + wm + wf + tau)
                or (stamp_ns - last) * 1e-9 * fs > 1.5
                or ((wu.twist_zero is None or not det.calibrated)
                    and (stamp_ns - g.t0_ns) * 1e-9 >= cfg.warmup_s)  # end of warm-up: block path
                or not hasattr(res.expected, "step_one") or res.irregular):  # rows of a replaced twin wait
            r = self.push(np.array([stamp_ns], np.int64), np.array([v], np.float64))
            for row in r.table:  # a fixed-lag twin may give several rows (or none) for one sample
                self.rows.append(row)
            self.events.extend(r.events)
            self.windows.extend(r.windows)
            return self.level
        g.health.n_samples += 1
        tm, tf = g.unwrap_one(stamp_ns, tm, wm, tf, wf)  # an angle arriving within one turn
        v = (tm, tf, wm, wf, tau, Q)
        t = (stamp_ns - g.t0_ns) * 1e-9
        h = g.hold
        h[0], h[1], h[2], h[3], h[4], h[5] = tm, tf, wm, wf, tau, Q
        g.last_ns = stamp_ns
        if res.delayed:  # a fixed-lag twin: the rows whose output came with this sample (usually the one lag back)
            lev = self.level
            for tk, sk, vk, out in res.one_delayed(t, stamp_ns, v):
                lev = self._one_row(tk, sk, vk, *out)
            return lev
        return self._one_row(t, stamp_ns, h, *res.one(t, tm, tf, wm, wf, tau, Q))

    def _one_row(self, t: float, stamp_ns: int, v, Q_hat: float, r_Q: float, Qt: float, tw_raw: float,
                 twist: float) -> int:
        """Warm-up, detection, row and window of one sample whose residuals are known (the short path)."""
        wu, det, cfg = self.warmup, self.detection, self.cfg
        tm, tf, wm, wf, tau, Q = v
        if wu.twist_zero is None:  # warm-up (t < warmup_s here)
            wu.one(t, tm, tf, wm, wf, tau, Q, tw_raw, Qt, r_Q, twist)
            r_tw = math.nan
        else:
            r_tw = math.nan if t < cfg.warmup_s else twist - wu.twist_zero
        if not det.calibrated:  # warm-up self-calibration data
            wu.lines_one(r_Q, twist, det.given_thresholds)
        lev, e_Q, e_tw, stiff, fric = det.one(t, stamp_ns, r_Q, r_tw, tw_raw, Qt, wm, self.events)
        row = (stamp_ns * 1e-9, Q, Q_hat, r_Q, e_Q, r_tw, e_tw, float(lev), stiff, fric)
        self.rows.append(row)
        w = self.win.one(t, row, v, self._close_window)
        if w is not None:
            self.windows.append(w)
        return lev

    def take_rows(self) -> np.ndarray:
        """Residual rows produced by :meth:`push_one` since the last call (n, len(RESIDUAL_COLUMNS))."""
        return self.rows.take()

    def take_events(self) -> list[tuple[int, int, str]]:
        ev, self.events = self.events, []
        return ev

    def take_windows(self) -> list[dict[str, Any]]:
        w, self.windows = self.windows, []
        return w
