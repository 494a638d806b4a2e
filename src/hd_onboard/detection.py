"""Detector orchestration of one actuator: residuals -> per-sample conditions -> held fault level -> events.

Per channel an EWMA detector (:class:`hd_onboard.detectors.ewma.ChannelDetector`) with the ground's lines
or, without them, lines self-calibrated on the warm-up (not evaluated before they exist); the
torsional-stiffness and friction monitors (:mod:`hd_onboard.detectors.stiffness`,
:mod:`hd_onboard.detectors.friction`) from the end of the warm-up that learns their references, or from
the first sample with the ground's; one :class:`hd_onboard.detectors.levels.LevelLatch` over all of them.
A rising level is an event ``(stamp_ns, level, reason)``, the reason naming the channels and monitors
above their WARN line. Block (:meth:`Detection.block`) and one-sample (:meth:`Detection.one`) paths give
the same numbers.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hd_onboard.detectors.ewma import ChannelDetector, ChannelThreshold
from hd_onboard.detectors.friction import FrictionMonitor, FrictionReference
from hd_onboard.detectors.levels import OK, LevelLatch
from hd_onboard.detectors.stiffness import StiffnessMonitor, StiffnessReference
from hd_onboard.residuals import CHANNELS


def given_reference(ref, cls, what: str):
    """A monitor reference given by the ground: None, an instance of ``cls``, or its dict (validated)."""
    if isinstance(ref, dict):
        ref = cls.from_dict(ref, what)
    if ref is not None and not isinstance(ref, cls):
        raise ValueError(f"{what}: expected {cls.__name__} or dict, got {type(ref).__name__}")
    return ref


class Detection:
    """Detectors, monitors, latch and level of one actuator; the ground's lines and references persist
    across missions, the rest restarts at :meth:`new_mission`."""

    def __init__(self, cfg, thresholds: dict[str, ChannelThreshold] | None = None):
        self.cfg = cfg
        self.given_thresholds = dict(thresholds or {})
        self.given_stiffness: StiffnessReference | None = None
        self.given_friction: FrictionReference | None = None

    def new_mission(self, fs: float | None) -> None:
        cfg = self.cfg
        self.calibrated = all(c in self.given_thresholds for c in CHANNELS)
        default = ChannelThreshold(0.0, 1.0, cfg.default_h_warn, cfg.default_h_error, "uncalibrated")
        self.detectors: dict[str, ChannelDetector] = {}
        for c in CHANNELS:
            self.detectors[c] = ChannelDetector(c, self.given_thresholds.get(c, default), 1.0, 1)
        self.latch = LevelLatch(cfg.hold_s)
        self.level = OK
        self.onset_ns: int | None = None
        self.stiffness = StiffnessMonitor(cfg.stiff_tau_s, cfg.stiff_loss_warn, cfg.stiff_loss_error, 1,
                                          cfg.stiff_min_excitation)
        self.friction = FrictionMonitor(cfg.fric_tau_s, cfg.fric_excess_warn, cfg.fric_excess_error, 1,
                                        cfg.fric_min_var_u)
        # a ground reference: monitor from the first sample; else from the end of the warm-up that learns it
        self.stiffness.ref = self.given_stiffness
        self.friction.ref = self.given_friction
        self.stiff_t0 = 0.0 if self.given_stiffness is not None else cfg.warmup_s  # s since mission start
        self.fric_t0 = 0.0 if self.given_friction is not None else cfg.warmup_s
        self.configure_rates(fs)
        self._es1 = {c: math.nan for c in CHANNELS}

    def configure_rates(self, fs: float | None) -> None:
        """EWMA factor and persistence counts for the joint-state rate ``fs`` [Hz] (None: 1 kHz until known)."""
        fs = fs or 1000.0
        cfg = self.cfg
        lam = min(1.0, 1.0 / (cfg.ewma_tau_s * fs))
        pers = max(1, int(round(cfg.persistence_s * fs)))
        for d in self.detectors.values():
            d.lam, d.persistence = lam, pers
        self.stiffness.set_rate(fs)
        self.stiffness.persistence = max(1, int(round(cfg.stiff_persistence_s * fs)))
        self.friction.set_rate(fs)
        self.friction.persistence = max(1, int(round(cfg.fric_persistence_s * fs)))

    # ---- lines and references ------------------------------------------------------------------------
    @property
    def thresholds(self) -> dict[str, ChannelThreshold]:
        return {c: d.threshold for c, d in self.detectors.items()}

    def set_thresholds(self, thresholds: dict[str, ChannelThreshold]) -> None:
        """The ground's lines (the EWMA state is kept)."""
        self.given_thresholds = dict(thresholds)
        for c, th in thresholds.items():
            if c in self.detectors:
                self.detectors[c].threshold = th
        self.calibrated = all(c in self.given_thresholds for c in CHANNELS)

    def apply_calibration(self, lines: dict[str, ChannelThreshold | None]) -> None:
        """Self-calibrated lines at the end of the warm-up (None: keep the default); the lines are known."""
        for c, th in lines.items():
            if th is not None:
                self.detectors[c].threshold = th
                self.detectors[c].reset()
        self.calibrated = True

    def set_stiffness_reference(self, ref) -> None:
        """The ground's torsion law (None: learnt on each mission's warm-up again, from the next mission)."""
        ref = given_reference(ref, StiffnessReference, "onboard stiffness reference")
        self.given_stiffness = ref
        if ref is not None:
            self.stiffness.ref = ref
            self.stiffness.reset()
            self.stiff_t0 = 0.0

    def set_friction_reference(self, ref) -> None:
        """The ground's friction mismatch (None: learnt on each mission's warm-up again, from the next mission)."""
        ref = given_reference(ref, FrictionReference, "onboard friction reference")
        self.given_friction = ref
        if ref is not None:
            self.friction.ref = ref
            self.friction.reset()
            self.fric_t0 = 0.0

    def learnt_references(self, stiffness: StiffnessReference | None, friction: FrictionReference | None) -> None:
        """End of the warm-up: its references, where the ground gave none."""
        if self.given_stiffness is None:
            self.stiffness.ref = stiffness
        if self.given_friction is None:
            self.friction.ref = friction

    # ---- status ---------------------------------------------------------------------------------------
    @staticmethod
    def _reference_label(ref, warming_up: bool) -> str:
        return ref.source if ref is not None else ("learning" if warming_up else "none")

    def stiffness_status(self, warming_up: bool) -> dict[str, Any]:
        sm = self.stiffness
        r = sm.ref
        return {"level": sm.level(), "loss": sm.loss, "compliance_ratio": sm.s, "loss_warn": sm.loss_warn,
                "loss_error": sm.loss_error, "n_eval": sm.n_eval,
                "reference": self._reference_label(r, warming_up),
                "compliance": r.compliance if r is not None else math.nan,
                "q_range": r.q_range if r is not None else math.nan}

    def friction_status(self, warming_up: bool) -> dict[str, Any]:
        fm = self.friction
        r = fm.ref
        return {"level": fm.level(), "excess": fm.excess, "excess_warn": fm.excess_warn,
                "excess_error": fm.excess_error, "n_eval": fm.n_eval,
                "reference": self._reference_label(r, warming_up),
                "b": r.b if r is not None else math.nan, "scale": r.scale if r is not None else math.nan}

    # ---- the two paths ------------------------------------------------------------------------------
    def block(self, t: np.ndarray, stamps_ns: np.ndarray, r_Q: np.ndarray, r_tw: np.ndarray, twist_raw: np.ndarray,
              Q_for_twist: np.ndarray, omega_m: np.ndarray, evaluate: np.ndarray):
        """A block -> ``(es, lev, stiff, fric, events)``: EWMA per channel (NaN where not evaluated), level,
        stiffness loss and friction excess per sample, rising-edge events."""
        cfg = self.cfg
        n = len(t)
        res = {"Q_red": r_Q, "twist": r_tw}
        cw = np.zeros(n, bool)
        ce = np.zeros(n, bool)
        es = {}
        for c, d in self.detectors.items():
            r = res[c]
            if c not in self.given_thresholds:
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
            after = t >= self.stiff_t0
            if after.any():
                stiff[after], sw[after], se_ = self.stiffness.step(twist_raw[after], Q_for_twist[after], omega_m[after],
                                                                   evaluate[after])
                cw |= sw
                ce[after] |= se_
        # friction / lubrication (after the warm-up that gave its reference; needs measured Q_red)
        fric = np.full(n, np.nan)
        fw = np.zeros(n, bool)
        if self.friction.ref is not None:
            after = t >= self.fric_t0
            if after.any():
                fric[after], fw[after], fe_ = self.friction.step(r_Q[after], omega_m[after], evaluate[after])
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
        return es, lev, stiff, fric, events

    def one(self, t: float, stamp_ns: int, r_Q: float, r_tw: float, tw_raw: float, Qt: float, wm: float, events: list):
        """One sample -> ``(level, e_Q_red, e_twist, stiffness loss, friction excess)``; a rising edge is appended
        to ``events``. Same arithmetic as :meth:`block`."""
        cfg = self.cfg
        given = self.given_thresholds
        lev_w = lev_e = False
        es = self._es1
        for c, r in (("Q_red", r_Q), ("twist", r_tw)):
            d = self.detectors[c]
            if c not in given and (t < cfg.warmup_s or not self.calibrated):
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
        if self.stiffness.ref is not None and t >= self.stiff_t0:
            stiff, s_w, s_e = self.stiffness.step_one(tw_raw, Qt, wm)
            lev_w = lev_w or s_w
            lev_e = lev_e or s_e
        fric = math.nan
        f_w = False
        if self.friction.ref is not None and t >= self.fric_t0:
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
            events.append((int(stamp_ns), int(lev), ",".join(which) or "held"))
            if self.onset_ns is None:
                self.onset_ns = int(stamp_ns)
        self.level = lev
        return lev, es["Q_red"], es["twist"], stiff, fric
