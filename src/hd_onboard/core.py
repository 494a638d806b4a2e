"""The onboard (real-time) core: conditioning -> expected response -> residuals -> flags -> windows.

Pure numpy, streaming, one actuator: the onboard node feeds it the blocks of
samples it takes from its subscriptions, :func:`run_mission` feeds it a whole
:class:`hd_bag.mission.Mission` in blocks (batch, tests, benchmarks, the
ground's threshold calibration): both produce the same numbers.

Signal conditioning (:meth:`OnboardCore.push`):

* stamps at or before the last accepted stamp (duplicates, late arrivals)
  are dropped and counted: a real-time monitor cannot wait to re-sort;
* a stamp step longer than ``max_gap_samples`` nominal periods is a dropout:
  the twin's state is reset (new segment) and the first ``settle_s`` seconds
  after it are not evaluated (filter / LSTM transient);
* NaN samples are held for the twin input and excluded from evaluation; a
  NaN run longer than ``max_gap_samples`` is treated like a dropout.

Residual channels (measured - expected):

* ``Q_red`` [N*m]: measured reducer output torque minus the twin's expected
  one (NaN where the bag does not measure Q_red);
* ``twist`` [rad]: transmission deflection not explained by the elastic
  law, ``(theta_f - theta_m/N) - Q/K_out`` (Q = measured Q_red, else the
  expected one), minus its value over the mission's first ``warmup_s``
  (encoder zero offsets). Lost motion, backlash and kinematic-error growth
  show here.

Each channel is normalised and tested by :mod:`hd_onboard.detectors`. Every
``window_s`` of sample time the core closes a window: residual statistics
per channel and, when available, the prognostic features of
``hd_onboard.features``; these rows go to the prognostic node.

Two entry points give the same numbers (tested to 1e-9):

* :meth:`OnboardCore.push` takes a block (vectorised; batch, replay at max rate);
* :meth:`OnboardCore.push_one` takes one sample (the real-time short path:
  scalar arithmetic, no temporary arrays, about 20x cheaper than a
  one-row block). Anything unusual for that sample (rate not yet known, NaN,
  a gap, the end of the warm-up) is handed to :meth:`push`.

With ``defer_windows = True`` a closed window is only captured (a copy of
its rows); its statistics and features, the costly part, are computed by
:func:`window_row` when the caller chooses (the node does it in a worker
thread), so closing a window never delays the flag decision of a sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hd_onboard.calibration import calibrate_channel
from hd_onboard.detectors.ewma import ChannelDetector, ChannelThreshold
from hd_onboard.detectors.friction import FrictionMonitor, FrictionReference, fit_friction_reference
from hd_onboard.detectors.levels import ERROR, OK, WARN, LevelLatch, run_lengths
from hd_onboard.detectors.stiffness import StiffnessMonitor, StiffnessReference, fit_stiffness_reference
from hd_onboard.expected import I_REF, I_TEMP, PhysicsStandInExpected
from hd_twin import physics as ph

JS_COLS = ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")
CHANNELS = ("Q_red", "twist")
#: columns of the residual table published on /hd/onboard/residuals
#: (``stiff_loss``: torsional-stiffness loss estimate 1 - 1/s of :class:`hd_onboard.detectors.stiffness.StiffnessMonitor`, NaN
#: where not evaluable; ``fric_excess``: friction excess of :class:`hd_onboard.detectors.friction.FrictionMonitor`, extra
#: output-referred friction torque in units of the twin's N*T_C, NaN where not evaluable or Q_red is not measured)
RESIDUAL_COLUMNS = ("stamp", "Q_red", "Q_red_hat", "r_Q_red", "e_Q_red", "r_twist", "e_twist", "level", "stiff_loss",
                    "fric_excess")
#: residual statistics per window and channel
STAT_NAMES = ("mean", "std", "rms", "max_abs_e", "frac_warn", "n_valid")


@dataclass
class OnboardConfig:
    """Onboard parameters (SI). Every one is a ROS parameter of the onboard node."""

    # Stiffness defaults chosen on the healthy tune fleet (bags/onboard_tune_fleet, seed 12) and on fault
    # missions of actuator 1 (pop seed 7, seeds 20-23); scored on other data (hd_onboard.evaluate.detection_study).
    # Residual lines: h_warn 5, persistence 0.2 s (was 3, 0.05 s) since lubrication loss is seen by the friction
    # monitor (the Q_red EWMA averages its direction-odd signature out): chosen on the tune fleet + unit 1 (false
    # alarms 8/16 -> 1/16, lubrication 2-3 still 8/8), scored on unit 2 + bags/onboard_fa_fleet (README).
    window_s: float = 1.0  # s, feature / residual-statistics window
    ewma_tau_s: float = 0.1  # s, EWMA time constant of the normalised residual
    persistence_s: float = 0.2  # s, the condition must hold this long before a flag rises
    hold_s: float = 2.0  # s, a raised flag is held at least this long
    warmup_s: float = 5.0  # s, twist zero and, without ground thresholds, self-calibration
    settle_s: float = 0.05  # s, not evaluated after a reset (filter / LSTM transient)
    max_gap_samples: int = 10  # dropout longer than this -> new segment
    nominal_fs: float = 0.0  # Hz; 0: estimated from the first stamps
    accel_cutoff_hz: float = 50.0  # Hz, stand-in derivative filter
    default_h_warn: float = 5.0  # sigma units, self-calibrated lines = max(default, margin * healthy peak)
    default_h_error: float = 6.0
    warn_margin: float = 1.5
    error_margin: float = 3.0
    sigma_floor_rel: float = 0.0  # -, self-calibration: sigma >= rel * std of the warm-up's output torque (twist: / K_out)
    # torsional-stiffness monitor (hd_onboard.detectors.stiffness.StiffnessMonitor); reference law learnt on the warm-up
    stiff_tau_s: float = 4.0  # s, forgetting time constant of the twist-vs-torque regression
    stiff_loss_warn: float = 0.15  # -, fraction of effective torsional stiffness lost -> WARN
    stiff_loss_error: float = 0.3  # -, -> ERROR
    stiff_persistence_s: float = 1.0  # s of consecutive evaluable samples above the line
    stiff_min_excitation: float = 0.5  # -, loaded-window gate: weighted std of g(Q) / the reference's
    stiff_eps_omega: float = 1.0  # rad/s, direction term tanh(omega_m / eps)
    # friction (lubrication) monitor (hd_onboard.detectors.friction.FrictionMonitor); reference learnt on the warm-up. Chosen on
    # the tune fleet and unit 1 (healthy excess peaks <= 1.95, lubrication loss 2-3 >= 3.6), scored on unit 2.
    fric_tau_s: float = 2.0  # s, forgetting time constant of the residual-vs-direction regression
    fric_excess_warn: float = 2.5  # -, extra friction torque / (N T_C of the twin) -> WARN
    fric_excess_error: float = 4.0  # -, -> ERROR
    fric_persistence_s: float = 0.5  # s of consecutive evaluable samples above the line
    fric_min_var_u: float = 0.05  # -, bidirectional-motion gate: weighted variance of tanh(omega_m / eps_omega)

    def validate(self) -> "OnboardConfig":
        for k in ("window_s", "ewma_tau_s", "persistence_s", "hold_s", "warmup_s", "default_h_warn",
                  "default_h_error", "warn_margin", "error_margin", "accel_cutoff_hz", "stiff_tau_s",
                  "stiff_loss_warn", "stiff_loss_error", "stiff_persistence_s", "stiff_min_excitation",
                  "stiff_eps_omega", "fric_tau_s", "fric_excess_warn", "fric_excess_error", "fric_persistence_s",
                  "fric_min_var_u"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"onboard parameter {k} = {v!r} must be a positive finite number")
        if not (0 <= self.settle_s < 60 and 1 <= int(self.max_gap_samples) <= 10**6):
            raise ValueError(f"onboard parameters settle_s={self.settle_s}, max_gap_samples={self.max_gap_samples} are absurd")
        if self.window_s > 3600 or self.ewma_tau_s > 3600:
            raise ValueError("onboard window_s / ewma_tau_s above one hour are absurd")
        if not (0.0 <= self.sigma_floor_rel <= 1.0):
            raise ValueError(f"onboard parameter sigma_floor_rel = {self.sigma_floor_rel} outside [0, 1]")
        if not (self.stiff_loss_warn <= self.stiff_loss_error < 1.0 and self.stiff_min_excitation <= 10):
            raise ValueError(f"onboard parameters stiff_loss_warn={self.stiff_loss_warn}, stiff_loss_error="
                             f"{self.stiff_loss_error} need warn <= error < 1; stiff_min_excitation <= 10")
        if not (self.fric_excess_warn <= self.fric_excess_error and self.fric_min_var_u < 1.0):
            raise ValueError(f"onboard parameters fric_excess_warn={self.fric_excess_warn}, fric_excess_error="
                             f"{self.fric_excess_error} need warn <= error; fric_min_var_u={self.fric_min_var_u} < 1")
        if not (self.nominal_fs == 0 or 10 <= self.nominal_fs <= 1e5):
            raise ValueError(f"onboard parameter nominal_fs = {self.nominal_fs} Hz outside 10..1e5 (0 = estimate)")
        return self


class _Buf:
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


@dataclass
class WindowJob:
    """A closed window captured for :func:`window_row` (rows copied; thresholds as they were)."""

    table: np.ndarray  # (n, len(RESIDUAL_COLUMNS))
    raw: np.ndarray  # (n, 6) samples, columns JS_COLS
    win_index: int
    window_s: float
    thresholds: dict  # channel -> ChannelThreshold
    temperature: float  # degC (NaN: unknown)


@dataclass
class InputHealth:
    """What conditioning did, for /diagnostics."""

    n_samples: int = 0
    n_dropped_order: int = 0  # duplicates / out-of-order stamps dropped
    n_nan: int = 0
    n_gaps: int = 0
    n_missing: int = 0  # samples missing in gaps
    n_resets: int = 0


@dataclass
class PushResult:
    table: np.ndarray  # (n, len(RESIDUAL_COLUMNS)), rows of accepted samples
    level: int  # level after the block
    events: list[tuple[int, int, str]] = field(default_factory=list)  # (stamp_ns, new level, reason) on rises
    windows: list[dict[str, Any]] = field(default_factory=list)


def _given_reference(ref, cls, what: str):
    """A monitor reference given by the ground: None, an instance of ``cls``, or its dict (validated)."""
    if isinstance(ref, dict):
        ref = cls.from_dict(ref, what)
    if ref is not None and not isinstance(ref, cls):
        raise ValueError(f"{what}: expected {cls.__name__} or dict, got {type(ref).__name__}")
    return ref


class OnboardCore:
    """Streaming residual / threshold / flag core for one actuator (see module docstring)."""

    def __init__(self, expected=None, params: ph.TwinParams | None = None, gear_ratio: float | None = None,
                 thresholds: dict[str, ChannelThreshold] | None = None, config: OnboardConfig | None = None,
                 feature_fn=None):
        self.cfg = (config or OnboardConfig()).validate()
        self.params = (params or ph.TwinParams.from_yaml())
        if gear_ratio is not None:
            self.params = self.params.with_meta(gear_ratio=gear_ratio)
        fs = self.cfg.nominal_fs or 1000.0
        #: the expected-response model configured for this core (each mission starts on it again);
        #: :attr:`expected` is the one running now (the physics stand-in after a fallback, see :meth:`input_status`)
        self.expected_configured = expected or PhysicsStandInExpected(self.params, fs_hz=fs,
                                                                      accel_cutoff_hz=self.cfg.accel_cutoff_hz)
        self.expected = self.expected_configured
        self.feature_fn = feature_fn
        self.defer_windows = False  # True: closed windows wait in window_jobs for window_row()
        self.window_jobs: list[WindowJob] = []
        self._given_thresholds = dict(thresholds or {})
        self._given_stiff_ref: StiffnessReference | None = None
        self._given_fric_ref: FrictionReference | None = None
        self.reset_mission()

    # ---- configuration -----------------------------------------------------
    def set_thresholds(self, thresholds: dict[str, ChannelThreshold]) -> None:
        """New per-channel thresholds (ground adaptation); the EWMA state is kept."""
        self._given_thresholds = dict(thresholds)
        for c, th in thresholds.items():
            if c in self.detectors:
                self.detectors[c].threshold = th
        self.calibrated = all(c in self._given_thresholds for c in CHANNELS)

    def set_params(self, params: ph.TwinParams) -> None:
        self.params = params.with_meta(gear_ratio=self.params.N)
        for e in {id(self.expected): self.expected, id(self.expected_configured): self.expected_configured}.values():
            if hasattr(e, "set_params"):
                e.set_params(self.params)

    def set_stiffness_reference(self, ref: "StiffnessReference | dict | None") -> None:
        """Healthy torsion law given by the ground (None: learn it on each mission's warm-up again).

        A ground reference wins over the warm-up's: it is applied at once (the monitor's moments
        restart: a twin update arriving mid-mission) and at every mission start, where the monitor
        then runs from the first sample instead of after the warm-up, so a stiffness loss already
        present at mission start is measured against the healthy law (the warm-up would learn the
        damaged one). The offset ``a`` is the ground's; the monitor's regression has its own
        intercept, so per-mission encoder offsets do not bias the compliance ratio. A dict is
        validated (:meth:`StiffnessReference.from_dict`); None takes effect at the next mission.
        """
        ref = _given_reference(ref, StiffnessReference, "onboard stiffness reference")
        self._given_stiff_ref = ref
        if ref is not None:
            self.stiffness.ref = ref
            self.stiffness.reset()
            self._stiff_t0 = 0.0

    def set_friction_reference(self, ref: "FrictionReference | dict | None") -> None:
        """Healthy friction mismatch given by the ground (None: learn it on each mission's warm-up again).

        Same rules as :meth:`set_stiffness_reference`: applied at once (moments restart) and at every
        mission start, monitoring from the first sample. The reference must have been fitted on residuals
        of the same twin (parameters and model) as this core's: the ground fits it with the parameters it
        pushes in the same update. A dict is validated (:meth:`FrictionReference.from_dict`).
        """
        ref = _given_reference(ref, FrictionReference, "onboard friction reference")
        self._given_fric_ref = ref
        if ref is not None:
            self.friction.ref = ref
            self.friction.reset()
            self._fric_t0 = 0.0

    def _reference_label(self, ref) -> str:
        """A monitor's reference for the status: its source, "learning" during the warm-up, "none" after it."""
        return ref.source if ref is not None else ("learning" if self._twist_zero is None else "none")

    def stiffness_status(self) -> dict[str, Any]:
        """State of the stiffness monitor for ``/diagnostics`` (``hdphm/onboard/stiffness``).

        ``level`` (OK/WARN/ERROR, persistence applied), ``loss`` (last evaluable stiffness loss
        1 - 1/s, -), ``compliance_ratio`` s, ``loss_warn``/``loss_error``, ``n_eval`` (evaluable
        samples this mission), ``reference`` (source, or "learning" during the warm-up, or
        "none" when the warm-up defined no torsion law: too little load variation), the
        reference's secant ``compliance`` [rad/(N*m)] and load range ``q_range`` [N*m].
        """
        sm = self.stiffness
        r = sm.ref
        return {"level": sm.level(), "loss": sm.loss, "compliance_ratio": sm.s, "loss_warn": sm.loss_warn,
                "loss_error": sm.loss_error, "n_eval": sm.n_eval,
                "reference": self._reference_label(r),
                "compliance": r.compliance if r is not None else math.nan,
                "q_range": r.q_range if r is not None else math.nan}

    def friction_status(self) -> dict[str, Any]:
        """State of the friction (lubrication) monitor for ``/diagnostics`` (``hdphm/onboard/friction``).

        ``level`` (OK/WARN/ERROR, persistence applied), ``excess`` (last evaluable friction excess, -,
        extra output-referred friction torque / ``scale``), ``excess_warn``/``excess_error``, ``n_eval``,
        ``reference`` (source, "learning" during the warm-up, or "none": no measured Q_red or no motion in
        both directions in the warm-up), the reference's ``b`` [N*m] and ``scale`` [N*m].
        """
        fm = self.friction
        r = fm.ref
        return {"level": fm.level(), "excess": fm.excess, "excess_warn": fm.excess_warn,
                "excess_error": fm.excess_error, "n_eval": fm.n_eval,
                "reference": self._reference_label(r),
                "b": r.b if r is not None else math.nan, "scale": r.scale if r is not None else math.nan}

    @property
    def thresholds(self) -> dict[str, ChannelThreshold]:
        return {c: d.threshold for c, d in self.detectors.items()}

    # ---- state -------------------------------------------------------------
    def reset_mission(self) -> None:
        """Forget everything of the current mission (a new mission starts)."""
        cfg = self.cfg
        self.fs = cfg.nominal_fs or None
        self._t0_ns: int | None = None
        self.last_ns: int | None = None
        self.last_valid_ns: int | None = None
        self._stamp_buf: list[int] = []
        self.health = InputHealth()
        self.temperature = math.nan
        self.theta_ref = math.nan
        self.expected = self.expected_configured
        self.expected.reset()
        #: input problems of this mission: key -> (level, message); see :meth:`input_status`
        self.input_notes: dict[str, tuple[int, str]] = {}
        self._notes_new: list[tuple[str, int, str]] = []
        self._twist_check: list[float] = []
        self._twist_checked = False
        self._raw_warm = _Buf(7, 8192)  # (t, JS_COLS) of the warm-up: unit / sign cross-checks at its end
        self._settle_until = -math.inf
        self._nan_run = 0
        self._hold = np.full(6, np.nan)
        self.calibrated = all(c in self._given_thresholds for c in CHANNELS)
        default = ChannelThreshold(0.0, 1.0, cfg.default_h_warn, cfg.default_h_error, "uncalibrated")
        self.detectors: dict[str, ChannelDetector] = {}
        for c in CHANNELS:
            self.detectors[c] = ChannelDetector(c, self._given_thresholds.get(c, default), 1.0, 1)
        self._configure_rates()
        self.latch = LevelLatch(cfg.hold_s)
        self.level = OK
        self.onset_ns: int | None = None
        self._warm: dict[str, _Buf] = {c: _Buf(None, 8192) for c in CHANNELS}
        self._twist_zero: float | None = None
        self._twist_warm = _Buf(None, 8192)
        self._win_index: int | None = None
        self._win = _Buf(len(RESIDUAL_COLUMNS))
        self._win_raw = _Buf(6)
        self.windows_emitted = 0
        self.window_jobs = []
        self.rows = _Buf(len(RESIDUAL_COLUMNS), 256)
        self.events: list[tuple[int, int, str]] = []
        self.windows: list[dict[str, Any]] = []
        self.stiffness = StiffnessMonitor(cfg.stiff_tau_s, cfg.stiff_loss_warn, cfg.stiff_loss_error, 1,
                                          cfg.stiff_min_excitation)
        self._stiff_warm = _Buf(3, 8192)  # (twist_raw, Q, omega_m) of the warm-up
        self.friction = FrictionMonitor(cfg.fric_tau_s, cfg.fric_excess_warn, cfg.fric_excess_error, 1,
                                        cfg.fric_min_var_u)
        self._fric_warm = _Buf(2, 8192)  # (r_Q, omega_m) of the warm-up
        # a ground reference: monitor from the first sample; else from the end of the warm-up that learns it
        self.stiffness.ref = self._given_stiff_ref
        self.friction.ref = self._given_fric_ref
        self._stiff_t0 = 0.0 if self._given_stiff_ref is not None else cfg.warmup_s  # s since mission start
        self._fric_t0 = 0.0 if self._given_fric_ref is not None else cfg.warmup_s
        self._warm_q_std = math.nan
        self._configure_rates()
        self._x1 = np.full(7, np.nan)
        self._es1 = {c: math.nan for c in CHANNELS}
        if self.fs is not None:
            self._rate_known()

    # ---- input guard ---------------------------------------------------------
    def _note(self, key: str, level: int, message: str) -> None:
        """Record an input problem of this mission (once per key; the highest level wins)."""
        old = self.input_notes.get(key)
        if old is None or level > old[0]:
            self.input_notes[key] = (int(level), message)
            self._notes_new.append((key, int(level), message))

    def take_input_notes(self) -> list[tuple[str, int, str]]:
        """Input problems recorded since the last call: ``(key, level, message)``, oldest first."""
        out, self._notes_new = self._notes_new, []
        return out

    def input_status(self) -> tuple[int, str]:
        """Worst input problem of this mission for ``/diagnostics``: ``(level, message)`` (OK, "ok" when none).

        Keys of :attr:`input_notes`: ``twin_rate`` (ERROR: the configured twin cannot run at the
        joint-state rate; physics-only stand-in used), ``twist_reference`` (WARN: theta_m and theta_f
        without a common zero; twist channels relative to the warm-up zero, twin replaced by the
        stand-in), ``speed_scale`` / ``torque_sign`` (WARN: unit or sign errors seen over the warm-up),
        ``short`` (WARN: the mission ended before the warm-up did: nothing evaluated).
        """
        if not self.input_notes:
            return OK, "ok"
        lev = max(v[0] for v in self.input_notes.values())
        return lev, "; ".join(m for _, m in sorted(self.input_notes.values(), key=lambda v: -v[0]))

    @property
    def fallback_reason(self) -> str:
        """Why the configured twin is not the one running ("" when it is)."""
        return getattr(self.expected, "fallback_reason", "") or ""

    def _use_standin(self, key: str, level: int, reason: str) -> None:
        """Safe mode: replace a trained twin by the physics-only stand-in for the rest of the mission."""
        cfg = self.cfg
        exp = PhysicsStandInExpected(self.params, fs_hz=self.fs or cfg.nominal_fs or 1000.0,
                                     accel_cutoff_hz=cfg.accel_cutoff_hz)
        exp.fallback_reason = reason
        self.expected = exp
        self._note(key, level, reason)

    def _rate_known(self, t_s: float | None = None) -> None:
        """The joint-state rate is known (at ``t_s`` s of the mission): the expected-response model is set up
        for it (``configure(fs_hz=...)``, a no-op when its rate is already that) or refused (see :meth:`input_status`)."""
        fs = float(self.fs)
        conf = getattr(self.expected, "configure", None)
        if conf is None or getattr(self.expected, "fs_in", None) == fs:
            return
        try:
            conf(fs_hz=fs)
        except ValueError as e:
            fm = getattr(self.expected, "fs_model", math.nan)
            self._use_standin("twin_rate", ERROR,
                              f"twin refused: trained at {fm:.1f} Hz, joint states at {fs:.1f} Hz ({e}); "
                              "physics-only stand-in used")
        if t_s is not None:  # a reconfigured model restarts: not evaluated for settle_s
            self._settle_until = max(self._settle_until, t_s + self.cfg.settle_s)

    def _check_twist_reference(self, V: np.ndarray) -> None:
        """First 16 valid samples: |median(theta_f - theta_m / N)| beyond any transmission twist
        (``hd_bag.mission.MAX_TWIST_OFFSET``) means encoders without a common zero (see :meth:`input_status`)."""
        from hd_bag.mission import MAX_TWIST_OFFSET

        tw = V[:, 1] - V[:, 0] / self.params.N
        self._twist_check += tw[np.isfinite(tw)][:16].tolist()
        if len(self._twist_check) < 16:
            return
        self._twist_checked = True
        med = float(np.median(self._twist_check))
        if abs(med) <= MAX_TWIST_OFFSET:
            return
        msg = (f"theta_f - theta_m / N = {med:.6g} rad (N = {self.params.N:g}), beyond any transmission twist "
               f"(> {MAX_TWIST_OFFSET:g} rad): encoders without a common zero; twist channel and stiffness monitor "
               "run relative to the warm-up's twist zero")
        if getattr(self.expected, "kind", "") == "onnx_twin":
            self._use_standin("twist_reference", WARN, msg + "; trained twin not fed this twist: physics-only stand-in used")
        else:
            self._note("twist_reference", WARN, msg)

    def _check_units(self) -> None:
        """End of the warm-up: the bag reader's unit / sign cross-checks (``hd_bag.reader``) on the warm-up samples."""
        w = self._raw_warm.take()
        if len(w) < 20:
            return
        from types import SimpleNamespace

        from hd_bag import reader as rd
        from hd_bag.mission import ReadReport

        rep = ReadReport()
        try:
            rd._consistency(SimpleNamespace(problems=[]), rep, w[:, 0], w[:, 1:], self.params.N)
        except (TypeError, AttributeError):  # the reader's internals changed: the check is skipped, said once
            self._note("unit_check", WARN, "unit / sign cross-checks unavailable (hd_bag.reader changed)")
            return
        for m in rep.suspect:
            key = "torque_sign" if "Q_red" in m else "speed_scale"
            self._note(key, WARN, m + " (over the warm-up; residual lines self-calibrate on it: detection unreliable)")

    def end_mission(self) -> None:
        """End of the mission (batch / a new /hd/mission): notes what could not be evaluated."""
        if self._t0_ns is not None and self._twist_zero is None and self.last_ns is not None:
            dur = (self.last_ns - self._t0_ns) * 1e-9
            self._note("short", WARN, f"mission of {dur:.3g} s ended inside the {self.cfg.warmup_s:g} s warm-up "
                       "(twist zero, self-calibration, monitor references): nothing evaluated")

    def _configure_rates(self) -> None:
        fs = self.fs or 1000.0
        lam = min(1.0, 1.0 / (self.cfg.ewma_tau_s * fs))
        pers = max(1, int(round(self.cfg.persistence_s * fs)))
        for d in self.detectors.values():
            d.lam, d.persistence = lam, pers
        sm = getattr(self, "stiffness", None)
        if sm is not None:
            sm.set_rate(fs)
            sm.persistence = max(1, int(round(self.cfg.stiff_persistence_s * fs)))
        fm = getattr(self, "friction", None)
        if fm is not None:
            fm.set_rate(fs)
            fm.persistence = max(1, int(round(self.cfg.fric_persistence_s * fs)))

    def push_temperature(self, stamp_ns: int, value: float) -> None:
        """A temperature sample [degC] (the gearbox frame is preferred by the caller)."""
        if math.isfinite(value) and -100.0 < value < 400.0:
            self.temperature = float(value)

    def push_command(self, stamp_ns: int, theta_ref: float) -> None:
        self.theta_ref = float(theta_ref)

    # ---- the hot path ------------------------------------------------------
    def push(self, stamps_ns: np.ndarray, V: np.ndarray) -> PushResult:
        """Process a block of joint-state samples.

        ``stamps_ns`` int64 (n,), ``V`` float (n, 6) with columns :data:`JS_COLS`
        (SI). Returns the residual table of the accepted samples, the level
        after the block, rising-edge events and the windows closed by the block.
        """
        cfg = self.cfg
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        V = np.asarray(V, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 6 or len(V) != len(stamps_ns):
            raise ValueError(f"onboard core: expected stamps (n,) and samples (n, 6), got {stamps_ns.shape} and {V.shape}")
        n_in = len(stamps_ns)
        self.health.n_samples += n_in
        if n_in == 0:
            return PushResult(np.empty((0, len(RESIDUAL_COLUMNS))), self.level)
        # 1. order: drop stamps not after everything accepted before
        prev = np.maximum.accumulate(np.concatenate([[self.last_ns if self.last_ns is not None else np.iinfo(np.int64).min], stamps_ns[:-1]]))
        keep = stamps_ns > prev
        if not keep.all():
            self.health.n_dropped_order += int((~keep).sum())
            stamps_ns, V = stamps_ns[keep], V[keep]
        n = len(stamps_ns)
        if n == 0:
            return PushResult(np.empty((0, len(RESIDUAL_COLUMNS))), self.level)
        if self._t0_ns is None:
            self._t0_ns = int(stamps_ns[0])
        # nominal rate from the first stamps (fixed once known)
        if self.fs is None:
            self._stamp_buf.extend(stamps_ns[:64].tolist())
            if len(self._stamp_buf) >= 16:
                d = np.diff(np.asarray(self._stamp_buf[:64]))
                d = d[d > 0]
                if len(d):
                    self.fs = 1e9 / float(np.median(d))
                    self._configure_rates()
                    self._rate_known((int(stamps_ns[0]) - self._t0_ns) * 1e-9)
        if not self._twist_checked:
            self._check_twist_reference(V)
        fs = self.fs or 1000.0
        t = (stamps_ns - self._t0_ns) * 1e-9  # s since mission start
        # 2. gaps and NaN -> resets and validity (Q_red may be absent: it is no twin input)
        valid = np.isfinite(V[:, :5]).all(axis=1)
        last = self.last_ns if self.last_ns is not None else int(stamps_ns[0])
        step = np.diff(np.concatenate([[last], stamps_ns])) * 1e-9 * fs
        gap = step > cfg.max_gap_samples + 0.5
        if (step > 1.5).any():
            big = step > 1.5
            self.health.n_gaps += int(big.sum())
            self.health.n_missing += int(np.round(step[big] - 1).sum())
        # NaN runs longer than max_gap_samples: a reset at the first valid sample after
        nanrun = self._nan_run
        reset_at = gap.copy()
        if not valid.all():
            self.health.n_nan += int((~valid).sum())
            runs = run_lengths(~valid, nanrun)
            after = np.concatenate([[nanrun], runs[:-1]])
            reset_at |= valid & (after > cfg.max_gap_samples)
            self._nan_run = int(runs[-1])
        else:
            self._nan_run = 0
        # 3. twin inputs: held NaN, temperature and command held
        Vh = V.copy()
        if not valid.all():
            prevrow = self._hold
            Vx = np.vstack([prevrow[None, :], Vh])
            ok = np.isfinite(Vx)
            idx = np.maximum.accumulate(np.where(ok, np.arange(len(Vx))[:, None], 0), axis=0)
            Vh = Vx[idx, np.arange(6)[None, :]][1:]
        X = np.empty((n, 7))
        X[:, 0] = Vh[:, 0]  # theta_m
        X[:, 1] = Vh[:, 2]  # omega_m
        X[:, 2] = Vh[:, 4]  # tau_m
        X[:, 3] = Vh[:, 1]  # theta_f
        X[:, 4] = Vh[:, 3]  # omega_f
        X[:, I_TEMP] = self.temperature
        X[:, I_REF] = self.theta_ref
        # 4. expected response, per segment (reset at dropouts)
        Q_hat = np.empty(n)
        settle_before = self._settle_until
        cuts = np.flatnonzero(reset_at)
        bounds = [0] + [int(c) for c in cuts if c > 0] + [n]
        if len(cuts) and cuts[0] == 0:
            self._reset_segment(t[0])
        for a, b in zip(bounds[:-1], bounds[1:]):
            if a > 0:
                self._reset_segment(t[a])
            Q_hat[a:b] = self.expected.step(t[a:b], X[a:b])
        self._hold = Vh[-1].copy()
        # 5. residuals
        Q_meas = V[:, 5]
        r_Q = Q_meas - Q_hat
        Q_for_twist = np.where(np.isfinite(Q_meas), Q_meas, Q_hat)
        twist_raw = V[:, 1] - V[:, 0] / self.params.N
        twist = twist_raw - Q_for_twist / self.params.K_out
        # not evaluated: settle_s after each reset (per sample: a reset late in the block masks only what follows it)
        settle = np.maximum(settle_before, np.maximum.accumulate(np.where(reset_at, t + cfg.settle_s, -np.inf)))
        evaluate = valid & (t >= settle)
        r_Q = np.where(evaluate, r_Q, np.nan)
        twist = np.where(evaluate, twist, np.nan)
        twist_raw = np.where(evaluate, twist_raw, np.nan)
        # twist zero over the warm-up
        if self._twist_zero is None:
            wm_ = t < cfg.warmup_s
            self._stiff_warm.extend(np.column_stack([twist_raw[wm_], Q_for_twist[wm_], V[wm_, 2]]))
            self._fric_warm.extend(np.column_stack([r_Q[wm_], V[wm_, 2]]))
            self._raw_warm.extend(np.column_stack([t[wm_], V[wm_]]))
            if t[-1] >= cfg.warmup_s:
                self._stiffness_reference()
                self._friction_reference()
                self._check_units()
            self._twist_warm.extend(twist[t < cfg.warmup_s])
            if t[-1] >= cfg.warmup_s:
                w = self._twist_warm.take()
                w = w[np.isfinite(w)]
                self._twist_zero = float(np.median(w)) if len(w) else 0.0
        if self._twist_zero is not None:
            r_tw = np.where(t < cfg.warmup_s, np.nan, twist - self._twist_zero)
        else:
            r_tw = np.full(n, np.nan)
        # 6. self-calibration when the ground has not given thresholds
        if not self.calibrated:
            self._self_calibrate(t, {"Q_red": r_Q, "twist": twist})
        # 7. detectors
        res = {"Q_red": r_Q, "twist": r_tw}
        cw = np.zeros(n, bool)
        ce = np.zeros(n, bool)
        es = {}
        for c, d in self.detectors.items():
            r = res[c]
            if c not in self._given_thresholds:
                # self-calibrated lines: the warm-up they were learnt on is not evaluated
                r = np.where(t < cfg.warmup_s, np.nan, r) if self.calibrated else np.full(n, np.nan)
            z, e, w_, e_ = d.step(r)
            es[c] = np.where(np.isfinite(r), e, np.nan)
            cw |= w_ & np.isfinite(r)
            ce |= e_ & np.isfinite(r)
        # torsional stiffness (after the warm-up that gave its reference)
        stiff = np.full(n, np.nan)
        sw = np.zeros(n, bool)
        if self.stiffness.ref is not None:
            after = t >= self._stiff_t0
            if after.any():
                stiff[after], sw[after], se_ = self.stiffness.step(twist_raw[after], Q_for_twist[after], V[after, 2],
                                                                   evaluate[after])
                cw |= sw
                ce[after] |= se_
        # friction / lubrication (after the warm-up that gave its reference; needs measured Q_red)
        fric = np.full(n, np.nan)
        fw = np.zeros(n, bool)
        if self.friction.ref is not None:
            after = t >= self._fric_t0
            if after.any():
                fric[after], fw[after], fe_ = self.friction.step(r_Q[after], V[after, 2], evaluate[after])
                cw |= fw
                ce[after] |= fe_
        lev = self.latch.step(t, cw, ce)
        events = []
        if len(lev):
            prev_level = self.level
            rises = np.flatnonzero(np.diff(np.concatenate([[prev_level], lev]).astype(int)) > 0)
            for i in rises:
                which = [c for c in CHANNELS if np.isfinite(es[c][i]) and abs(es[c][i]) > self.detectors[c].threshold.h_warn]
                if sw[i]:
                    which.append("stiffness")
                if fw[i]:
                    which.append("friction")
                events.append((int(stamps_ns[i]), int(lev[i]), ",".join(which) or "held"))
                if self.onset_ns is None:
                    self.onset_ns = int(stamps_ns[i])
            self.level = int(lev[-1])
        table = np.column_stack([stamps_ns * 1e-9, Q_meas, Q_hat, r_Q, es["Q_red"], r_tw, es["twist"], lev.astype(float), stiff, fric])
        self.last_ns = int(stamps_ns[-1])
        # 8. windows
        windows = self._windows(t, stamps_ns, table, V, evaluate)
        return PushResult(table, self.level, events, windows)

    def _reset_segment(self, t_s: float) -> None:
        self.expected.reset()
        self.health.n_resets += 1
        self._settle_until = t_s + self.cfg.settle_s

    def _stiffness_reference(self) -> None:
        """End of the warm-up: the healthy torsion law learnt on it (kept: the ground's, when given)."""
        w = self._stiff_warm.take()
        cfg = self.cfg
        q = w[:, 1][np.isfinite(w[:, 1])]
        self._warm_q_std = float(np.std(q)) if len(q) > 1 else math.nan  # N*m, scale of the self-calibration floor
        if self._given_stiff_ref is not None:
            return
        self.stiffness.ref = fit_stiffness_reference(w[:, 0], w[:, 1], w[:, 2], cfg.stiff_eps_omega)

    def _friction_reference(self) -> None:
        """End of the warm-up: this unit's healthy friction mismatch (None without measured Q_red or bidirectional motion)."""
        w = self._fric_warm.take()
        p = self.params
        if self._given_fric_ref is not None:
            return
        self.friction.ref = fit_friction_reference(w[:, 0], w[:, 1], p.eps_omega, p.N * p.T_C)

    def _self_calibrate(self, t: np.ndarray, res: dict[str, np.ndarray]) -> None:
        """Lines from the first ``warmup_s`` of the mission (used only when the ground gave none)."""
        cfg = self.cfg
        for c in CHANNELS:
            if c in self._given_thresholds:
                continue
            self._warm[c].extend(res[c][t < cfg.warmup_s])
        if t[-1] < cfg.warmup_s:
            return
        fs = self.fs or 1000.0
        for c in CHANNELS:
            if c in self._given_thresholds:
                continue
            r = self._warm[c].take()
            if c == "twist":
                r = r - (self._twist_zero if self._twist_zero is not None else np.nanmedian(r) if np.isfinite(r).any() else 0.0)
            floor = cfg.sigma_floor_rel * self._warm_q_std / (self.params.K_out if c == "twist" else 1.0)
            th = calibrate_channel(r, fs=fs, ewma_tau_s=cfg.ewma_tau_s, persistence_s=cfg.persistence_s,
                                   warn_margin=cfg.warn_margin, error_margin=cfg.error_margin,
                                   min_h_warn=cfg.default_h_warn, min_h_error=cfg.default_h_error,
                                   sigma_floor=floor)
            if th is not None:
                self.detectors[c].threshold = th
                self.detectors[c].reset()
        self.calibrated = True

    def _windows(self, t, stamps_ns, table, V, evaluate) -> list[dict[str, Any]]:
        w = self.cfg.window_s
        widx = np.floor(t / w).astype(np.int64)
        out = []
        if self._win_index is None:
            self._win_index = int(widx[0])
        cut = np.flatnonzero(widx != self._win_index)
        start = 0
        while len(cut):
            c = int(cut[0])
            self._win.extend(table[start:c])
            self._win_raw.extend(V[start:c])
            out.append(self._close_window())
            self._win_index = int(widx[c])
            start = c
            cut = np.flatnonzero(widx[start:] != self._win_index) + start
        self._win.extend(table[start:])
        self._win_raw.extend(V[start:])
        return [o for o in out if o is not None]

    def _close_window(self) -> dict[str, Any] | None:
        """Capture the open window; its row now (None if deferred or empty)."""
        if len(self._win) == 0:
            self._win_raw.take()
            return None
        job = WindowJob(self._win.take(), self._win_raw.take(), int(self._win_index), self.cfg.window_s,
                        {c: d.threshold for c, d in self.detectors.items()}, self.temperature)
        self.windows_emitted += 1
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

        ``v``: the 6 values of :data:`JS_COLS` (SI, a sequence of floats).
        Same arithmetic as :meth:`push` on a one-row block, in scalars. The
        residual row is appended to :attr:`rows` (take them with
        :meth:`take_rows`); rising edges go to :attr:`events`; closed
        windows are returned by :meth:`take_windows` (or queued as jobs in
        deferred mode).
        """
        fs = self.fs
        last = self.last_ns
        tm, tf, wm, wf, tau, Q = v
        # the cases the short path does not handle go through the block path
        cfg = self.cfg
        if (fs is None or last is None or stamp_ns <= last or self._nan_run or not self._twist_checked
                or not math.isfinite(tm + tf + wm + wf + tau)
                or (stamp_ns - last) * 1e-9 * fs > 1.5
                or ((self._twist_zero is None or not self.calibrated)
                    and (stamp_ns - self._t0_ns) * 1e-9 >= cfg.warmup_s)  # end of warm-up: block path
                or not hasattr(self.expected, "step_one")):
            r = self.push(np.array([stamp_ns], np.int64), np.array([v], np.float64))
            if len(r.table):
                self.rows.append(r.table[0])
            self.events.extend(r.events)
            self.windows.extend(r.windows)
            return self.level
        self.health.n_samples += 1
        t = (stamp_ns - self._t0_ns) * 1e-9
        x = self._x1
        x[0], x[1], x[2], x[3], x[4] = tm, wm, tau, tf, wf
        x[I_TEMP] = self.temperature
        x[I_REF] = self.theta_ref
        Q_hat = float(self.expected.step_one(t, x))
        h = self._hold
        h[0], h[1], h[2], h[3], h[4], h[5] = tm, tf, wm, wf, tau, Q
        p = self.params
        r_Q = Q - Q_hat  # NaN when Q_red is not measured
        Qt = Q if Q == Q else Q_hat
        tw_raw = tf - tm / p.N
        twist = tw_raw - Qt / p.K_out
        if t < self._settle_until:
            r_Q = twist = tw_raw = math.nan
        if self._twist_zero is None:  # warm-up (t < warmup_s here)
            self._twist_warm.append(twist)
            self._stiff_warm.append((tw_raw, Qt, wm))
            self._fric_warm.append((r_Q, wm))
            self._raw_warm.append((t, tm, tf, wm, wf, tau, Q))
            r_tw = math.nan
        else:
            r_tw = math.nan if t < cfg.warmup_s else twist - self._twist_zero
        if not self.calibrated:  # warm-up self-calibration data
            for c, r in (("Q_red", r_Q), ("twist", twist)):
                if c not in self._given_thresholds:
                    self._warm[c].append(r)
        lev_w = lev_e = False
        es = self._es1
        for c, r in (("Q_red", r_Q), ("twist", r_tw)):
            d = self.detectors[c]
            if c not in self._given_thresholds and (t < cfg.warmup_s or not self.calibrated):
                r = math.nan
            e, w_, e_ = d.step_one(r)
            if r == r:
                es[c] = e
                lev_w = lev_w or w_
                lev_e = lev_e or e_
            else:
                es[c] = math.nan
        stiff = math.nan
        s_w = False
        if self.stiffness.ref is not None and t >= self._stiff_t0:
            stiff, s_w, s_e = self.stiffness.step_one(tw_raw, Qt, wm)
            lev_w = lev_w or s_w
            lev_e = lev_e or s_e
        fric = math.nan
        f_w = False
        if self.friction.ref is not None and t >= self._fric_t0:
            fric, f_w, f_e = self.friction.step_one(r_Q, wm)
            lev_w = lev_w or f_w
            lev_e = lev_e or f_e
        lev = self.latch.step_one(t, lev_w, lev_e)
        if lev > self.level:
            which = [c for c in CHANNELS if es[c] == es[c] and abs(es[c]) > self.detectors[c].threshold.h_warn]
            if s_w:
                which.append("stiffness")
            if f_w:
                which.append("friction")
            self.events.append((int(stamp_ns), int(lev), ",".join(which) or "held"))
            if self.onset_ns is None:
                self.onset_ns = int(stamp_ns)
        self.level = lev
        row = (stamp_ns * 1e-9, Q, Q_hat, r_Q, es["Q_red"], r_tw, es["twist"], float(lev), stiff, fric)
        self.rows.append(row)
        self.last_ns = stamp_ns
        wi = math.floor(t / cfg.window_s)
        if wi != self._win_index:
            if self._win_index is None:
                self._win_index = wi
            else:
                w = self._close_window()
                self._win_index = wi
                if w is not None:
                    self.windows.append(w)
        self._win.append(row)
        self._win_raw.append(h)
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


def run_mission(mission, core: OnboardCore | None = None, block: int = 1000, **kw) -> dict[str, Any]:
    """Batch: stream a whole Mission through an :class:`OnboardCore` in blocks of ``block`` samples.

    Temperatures and commands are pushed in stamp order between the blocks.
    Returns ``table`` (residual rows), ``windows`` (list of dicts), ``events``,
    ``level`` (final), ``max_level``, ``onset_s`` (first rise, s since the
    mission start or None), ``health`` (conditioning counts), ``core``.
    """
    if core is None:
        core = OnboardCore(gear_ratio=mission.meta.gear_ratio, **kw)
    t0 = mission.t0_ns
    stamps = t0 + np.round(mission.t * 1e9).astype(np.int64)
    V = np.column_stack([mission.theta_m, mission.theta_f, mission.omega_m, mission.omega_f, mission.tau_m, mission.Q_red])
    temps = []
    for frame, (tt, vv) in mission.temperatures.items():
        if frame == "gearbox" or "gearbox" not in mission.temperatures:
            temps = list(zip((t0 + np.round(np.asarray(tt) * 1e9)).astype(np.int64).tolist(), np.asarray(vv).tolist()))
            break
    cmds = list(zip((t0 + np.round(np.asarray(mission.t_cmd) * 1e9)).astype(np.int64).tolist(),
                    np.asarray(mission.theta_ref).tolist()))
    ti = ci = 0
    tables, windows, events = [], [], []
    for a in range(0, len(stamps), block):
        b = min(a + block, len(stamps))
        s0 = stamps[a]
        while ti < len(temps) and temps[ti][0] <= s0:
            core.push_temperature(*temps[ti])
            ti += 1
        while ci < len(cmds) and cmds[ci][0] <= s0:
            core.push_command(*cmds[ci])
            ci += 1
        r = core.push(stamps[a:b], V[a:b])
        tables.append(r.table)
        windows += r.windows
        events += r.events
    windows += core.flush()
    core.end_mission()
    table = np.concatenate(tables) if tables else np.empty((0, len(RESIDUAL_COLUMNS)))
    max_level = int(table[:, 7].max()) if len(table) else OK
    return {
        "table": table,
        "windows": windows,
        "events": events,
        "level": core.level,
        "max_level": max_level,
        "onset_s": None if core.onset_ns is None else (core.onset_ns - t0) * 1e-9,
        "health": core.health,
        "core": core,
        "input": core.input_status(),  # (level, message): input problems and fallbacks (OnboardCore.input_status)
    }


LEVELS = (OK, WARN, ERROR)
