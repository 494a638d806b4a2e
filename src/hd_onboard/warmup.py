"""The warm-up: what the first ``warmup_s`` seconds of a mission teach the onboard core.

Over the warm-up nothing is evaluated (except channels and monitors whose lines or references the
ground gave); at its end:

* the twist zero: median of the twist channel over the warm-up (encoder zero offsets);
* the monitors' healthy references (:func:`hd_onboard.detectors.stiffness.fit_stiffness_reference`,
  :func:`hd_onboard.detectors.friction.fit_friction_reference`), unless the ground gave them;
* the self-calibrated alarm lines of each channel the ground gave no lines for
  (:func:`hd_onboard.calibration.calibrate_channel`, scale floor from the warm-up's load range);
* the warm-up samples for the input guard's unit / sign cross-checks.
"""

from __future__ import annotations

import math

import numpy as np

from hd_onboard.buffer import RowBuffer
from hd_onboard.calibration import calibrate_channel
from hd_onboard.detectors.ewma import ChannelThreshold
from hd_onboard.detectors.friction import FrictionReference, fit_friction_reference
from hd_onboard.detectors.stiffness import StiffnessReference, fit_stiffness_reference
from hd_onboard.residuals import CHANNELS


class WarmUp:
    """Warm-up samples and what is learnt from them, for one mission (a new one per mission)."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.twist_zero: float | None = None  # rad; None: the warm-up is not over
        self.q_std = math.nan  # N*m, std of the warm-up's output torque (scale of the self-calibration floor)
        #: references learnt at the end of the warm-up (None: not learnt; the ground's are kept when given)
        self.stiffness_ref: StiffnessReference | None = None
        self.friction_ref: FrictionReference | None = None
        self._lines = {c: RowBuffer(None, 8192) for c in CHANNELS}  # residuals for the self-calibration
        self._twist = RowBuffer(None, 8192)
        self._stiff = RowBuffer(3, 8192)  # (twist_raw, Q, omega_m)
        self._fric = RowBuffer(2, 8192)  # (r_Q, omega_m)
        self._raw = RowBuffer(7, 8192)  # (t, JS_COLS): unit / sign cross-checks at its end

    @property
    def done(self) -> bool:
        return self.twist_zero is not None

    def take_raw(self) -> np.ndarray:
        """The warm-up's samples (rows ``t, JS_COLS``), for the input guard's cross-checks; then empty."""
        return self._raw.take()

    # ---- collection --------------------------------------------------------------------------------
    def block(self, t: np.ndarray, V: np.ndarray, twist_raw: np.ndarray, Q_for_twist: np.ndarray, r_Q: np.ndarray,
              twist: np.ndarray, params, given_stiffness: bool, given_friction: bool) -> bool:
        """Collect a block's warm-up samples (``t`` < ``warmup_s``); True when the warm-up ends in it
        (twist zero and references then known)."""
        cfg = self.cfg
        wm_ = t < cfg.warmup_s
        self._stiff.extend(np.column_stack([twist_raw[wm_], Q_for_twist[wm_], V[wm_, 2]]))
        self._fric.extend(np.column_stack([r_Q[wm_], V[wm_, 2]]))
        self._raw.extend(np.column_stack([t[wm_], V[wm_]]))
        end = t[-1] >= cfg.warmup_s
        if end:
            self._stiffness_reference(given_stiffness)
            self._friction_reference(params, given_friction)
        self._twist.extend(twist[t < cfg.warmup_s])
        if end:
            w = self._twist.take()
            w = w[np.isfinite(w)]
            self.twist_zero = float(np.median(w)) if len(w) else 0.0
        return end

    def one(self, t: float, tm: float, tf: float, wm: float, wf: float, tau: float, Q: float, tw_raw: float,
            Qt: float, r_Q: float, twist: float) -> None:
        """Collect one warm-up sample (the short path; the sample ending the warm-up takes the block path)."""
        self._twist.append(twist)
        self._stiff.append((tw_raw, Qt, wm))
        self._fric.append((r_Q, wm))
        self._raw.append((t, tm, tf, wm, wf, tau, Q))

    def lines_one(self, r_Q: float, twist: float, given: dict) -> None:
        """One sample's residuals for the self-calibration of the channels without ground lines."""
        for c, r in (("Q_red", r_Q), ("twist", twist)):
            if c not in given:
                self._lines[c].append(r)

    # ---- what is learnt ----------------------------------------------------------------------------
    def _stiffness_reference(self, given: bool) -> None:
        """End of the warm-up: the healthy torsion law learnt on it (not fitted when the ground gave one)."""
        w = self._stiff.take()
        cfg = self.cfg
        q = w[:, 1][np.isfinite(w[:, 1])]
        self.q_std = float(np.std(q)) if len(q) > 1 else math.nan
        if given:
            return
        self.stiffness_ref = fit_stiffness_reference(w[:, 0], w[:, 1], w[:, 2], cfg.stiff_eps_omega)

    def _friction_reference(self, p, given: bool) -> None:
        """End of the warm-up: this unit's healthy friction mismatch (None without measured Q_red or bidirectional motion)."""
        w = self._fric.take()
        if given:
            return
        self.friction_ref = fit_friction_reference(w[:, 0], w[:, 1], p.eps_omega, p.N * p.T_C)

    def self_calibrate(self, t: np.ndarray, res: dict[str, np.ndarray], fs: float, K_out: float,
                       given: dict) -> dict[str, ChannelThreshold | None] | None:
        """Lines from the first ``warmup_s`` of the mission for the channels not in ``given`` (the ground's):
        None while the warm-up goes on, else channel -> lines (None: too few samples)."""
        cfg = self.cfg
        for c in CHANNELS:
            if c in given:
                continue
            self._lines[c].extend(res[c][t < cfg.warmup_s])
        if t[-1] < cfg.warmup_s:
            return None
        out = {}
        for c in CHANNELS:
            if c in given:
                continue
            r = self._lines[c].take()
            if c == "twist":
                r = r - (self.twist_zero if self.twist_zero is not None else np.nanmedian(r) if np.isfinite(r).any() else 0.0)
            floor = cfg.sigma_floor_rel * self.q_std / (K_out if c == "twist" else 1.0)
            out[c] = calibrate_channel(r, fs=fs, ewma_tau_s=cfg.ewma_tau_s, persistence_s=cfg.persistence_s,
                                       warn_margin=cfg.warn_margin, error_margin=cfg.error_margin,
                                       min_h_warn=cfg.default_h_warn, min_h_error=cfg.default_h_error,
                                       sigma_floor=floor)
        return out
