"""Residual channels of one actuator: the expected response (the twin running now) and measured - expected.

Channels (:data:`CHANNELS`):

* ``Q_red`` [N*m]: measured reducer output torque minus the twin's expected
  one (NaN where the bag does not measure Q_red);
* ``twist`` [rad]: transmission deflection not explained by the elastic
  law, ``(theta_f - theta_m/N) - Q/K_out`` (Q = measured Q_red, else the
  expected one); the warm-up (:mod:`hd_onboard.warmup`) gives the zero it is
  measured from (encoder zero offsets).

:class:`Residuals` owns the expected-response model: the one configured for
the core (each mission starts on it again) and the one running now (the
physics-only stand-in after a fallback: a twin refusing the joint-state rate,
or encoders without a common zero fed to a trained twin). It resets the model
at a dropout (new segment) and masks the first ``settle_s`` seconds after a
reset (filter / LSTM transient). Block (:meth:`Residuals.block`) and one-sample
(:meth:`Residuals.one`) paths give the same numbers.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from hd_onboard.detectors.levels import ERROR, WARN
from hd_onboard.expected import I_REF, I_TEMP, PhysicsStandInExpected
from hd_twin import physics as ph

#: joint-state sample columns (SI) the core takes
JS_COLS = ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")
#: residual channels tested by the EWMA detectors
CHANNELS = ("Q_red", "twist")
#: columns of the residual table published on /hd/onboard/residuals
#: (``stiff_loss``: torsional-stiffness loss estimate 1 - 1/s of :class:`hd_onboard.detectors.stiffness.StiffnessMonitor`, NaN
#: where not evaluable; ``fric_excess``: friction excess of :class:`hd_onboard.detectors.friction.FrictionMonitor`, extra
#: output-referred friction torque in units of the twin's N*T_C, NaN where not evaluable or Q_red is not measured)
RESIDUAL_COLUMNS = ("stamp", "Q_red", "Q_red_hat", "r_Q_red", "e_Q_red", "r_twist", "e_twist", "level", "stiff_loss",
                    "fric_excess")

#: records an input problem: ``note(key, level, message)`` (:meth:`hd_onboard.guard.InputGuard.note`)
Note = Callable[[str, int, str], None]


class BlockResiduals(NamedTuple):
    """Residuals of a block of accepted samples (NaN where not evaluated, see ``evaluate``)."""

    Q_meas: np.ndarray  # N*m, measured Q_red (NaN: not measured)
    Q_hat: np.ndarray  # N*m, expected Q_red
    r_Q: np.ndarray  # N*m, Q_meas - Q_hat
    Q_for_twist: np.ndarray  # N*m, measured Q_red, else the expected one
    twist_raw: np.ndarray  # rad, theta_f - theta_m / N
    twist: np.ndarray  # rad, twist_raw - Q_for_twist / K_out (before the warm-up's zero)
    evaluate: np.ndarray  # bool, valid sample outside a settle interval
    n_resets: int  # model resets (dropouts) in the block
    # the rows these residuals belong to (a fixed-lag twin gives them lag samples late: earlier rows than the
    # block's, and fewer or more of them); all None: the block's rows (OnboardCore.push fills them in)
    t: np.ndarray | None = None  # s since mission start
    stamps: np.ndarray | None = None  # ns
    V: np.ndarray | None = None  # samples (columns JS_COLS)


class Residuals:
    """Expected response and residual channels of one actuator (see module docstring)."""

    def __init__(self, expected, params: ph.TwinParams, cfg):
        self.cfg = cfg
        self.params = params
        #: the expected-response model configured for the core (each mission starts on it again);
        #: :attr:`expected` is the one running now (the physics stand-in after a fallback)
        self.expected_configured = expected or PhysicsStandInExpected(params, fs_hz=cfg.nominal_fs or 1000.0,
                                                                      accel_cutoff_hz=cfg.accel_cutoff_hz)
        set_mode = getattr(self.expected_configured, "set_mode", None)
        if set_mode is not None:  # a trained twin: causal or fixed lag (OnboardConfig.twin_fixed_lag)
            set_mode("fixed_lag" if cfg.twin_fixed_lag else "causal")
        self.expected = self.expected_configured
        self._queue: tuple | None = None  # rows waiting for a fixed-lag twin's output: (t, stamps, V, ok)
        self._carry: np.ndarray | None = None  # Q_hat of queued rows from a model no longer running

    def new_mission(self) -> None:
        """The configured model again, reset; temperature and command unknown; the mission start is a reset
        too: not evaluated for :meth:`settle_s` (the twin's derivative window is not filled there, and a
        mission that starts with a step in acceleration gave the twin's largest errors on its first samples)."""
        self.temperature = math.nan  # degC, last plausible temperature sample
        self.theta_ref = math.nan  # rad, last command
        self.expected = self.expected_configured
        self.expected.reset()
        self.settle_until = self.settle_s  # s since mission start: not evaluated before
        self._x1 = np.full(7, np.nan)
        self._queue = None
        self._carry = None

    @property
    def lag_samples(self) -> int:
        """Rows between a sample's arrival and its residual (a fixed-lag twin; 0 otherwise)."""
        return int(getattr(self.expected, "lag_samples", 0) or 0)

    @property
    def delayed(self) -> bool:
        """The model running now answers for earlier rows (a fixed-lag twin): rows wait in a queue."""
        return bool(getattr(self.expected, "delayed", False))

    @property
    def settle_s(self) -> float:
        """Seconds not evaluated after a model reset: ``cfg.settle_s`` (filter / LSTM transient), at least the
        running model's edge interval (``edge_s``: :attr:`hd_twin.runtime.StreamingTwin.edge_s`; 0 for the
        physics-only stand-in)."""
        return max(float(self.cfg.settle_s), float(self.expected.edge_s))

    def set_params(self, params: ph.TwinParams) -> None:
        """New twin parameters (the gear ratio is kept), given to both models."""
        self.params = params.with_meta(gear_ratio=self.params.N)
        for e in {id(self.expected): self.expected, id(self.expected_configured): self.expected_configured}.values():
            if hasattr(e, "set_params"):
                e.set_params(self.params)

    @property
    def fallback_reason(self) -> str:
        """Why the configured twin is not the one running ("" when it is)."""
        return getattr(self.expected, "fallback_reason", "") or ""

    # ---- fallbacks -------------------------------------------------------------------------------
    def use_standin(self, fs: float | None, key: str, level: int, reason: str, note: Note) -> None:
        """Safe mode: replace a trained twin by the physics-only stand-in for the rest of the mission."""
        cfg = self.cfg
        exp = PhysicsStandInExpected(self.params, fs_hz=fs or cfg.nominal_fs or 1000.0,
                                     accel_cutoff_hz=cfg.accel_cutoff_hz)
        exp.fallback_reason = reason
        self._hold_back()
        self.expected = exp
        note(key, level, reason)

    def rate_known(self, fs: float, t_s: float | None, note: Note) -> None:
        """The joint-state rate ``fs`` [Hz] is known (at ``t_s`` s of the mission): the expected-response model is
        set up for it (``configure(fs_hz=...)``, a no-op when its rate is already that) or refused (ERROR
        ``twin_rate``, physics-only stand-in)."""
        fs = float(fs)
        conf = getattr(self.expected, "configure", None)
        if conf is None or getattr(self.expected, "fs_in", None) == fs:
            return
        self._hold_back()  # configure resets the model
        try:
            conf(fs_hz=fs)
        except ValueError as e:
            fm = getattr(self.expected, "fs_model", math.nan)
            self.use_standin(fs, "twin_rate", ERROR,
                             f"twin refused: trained at {fm:.1f} Hz, joint states at {fs:.1f} Hz ({e}); "
                             "physics-only stand-in used", note)
        if t_s is not None:  # a reconfigured model restarts: not evaluated for settle_s
            self.settle_until = max(self.settle_until, t_s + self.settle_s)

    def twist_reference_problem(self, fs: float | None, msg: str, note: Note) -> None:
        """Encoders without a common zero (:meth:`hd_onboard.guard.InputGuard.check_twist_reference`): a trained
        twin is not fed this twist (stand-in); the problem is recorded either way (WARN ``twist_reference``)."""
        if getattr(self.expected, "kind", "") == "onnx_twin":
            self.use_standin(fs, "twist_reference", WARN,
                             msg + "; trained twin not fed this twist: physics-only stand-in used", note)
        else:
            note("twist_reference", WARN, msg)

    # ---- the two paths ---------------------------------------------------------------------------
    def block(self, t: np.ndarray, V: np.ndarray, Vh: np.ndarray, valid: np.ndarray,
              reset_at: np.ndarray, stamps: np.ndarray | None = None) -> BlockResiduals:
        """Residuals of a block: ``t`` [s since mission start], ``V`` samples (columns :data:`JS_COLS`), ``Vh``
        the same with NaN held (twin input), ``valid`` rows, ``reset_at`` rows starting a new segment,
        ``stamps`` [ns].

        A fixed-lag twin (``lag_samples`` > 0) gives Q_hat ``lag_samples`` rows late: the rows wait here and the
        residuals come for the rows whose Q_hat is known (``t``, ``stamps``, ``V`` of the result; residual k is
        measurement k minus Q_hat k); at a reset the previous segment's last rows come out (not evaluated:
        the batch twin's edge samples), the rest at :meth:`drain`."""
        cfg = self.cfg
        n = len(t)
        # twin inputs: held NaN, temperature and command held
        X = np.empty((n, 7))
        X[:, 0] = Vh[:, 0]  # theta_m
        X[:, 1] = Vh[:, 2]  # omega_m
        X[:, 2] = Vh[:, 4]  # tau_m
        X[:, 3] = Vh[:, 1]  # theta_f
        X[:, 4] = Vh[:, 3]  # omega_f
        X[:, I_TEMP] = self.temperature
        X[:, I_REF] = self.theta_ref
        # expected response, per segment (reset at dropouts); a fixed-lag twin answers for earlier rows (queued)
        settle_before = self.settle_until
        cuts = np.flatnonzero(reset_at)
        bounds = [0] + [int(c) for c in cuts if c > 0] + [n]
        n_resets = 0
        # not evaluated: settle_s after each reset (per sample: a reset late in the block masks only what follows it)
        settle = np.maximum(settle_before, np.maximum.accumulate(np.where(reset_at, t + self.settle_s, -np.inf)))
        ok = valid & (t >= settle)
        lagged = self.delayed or self._queue is not None
        if lagged:
            st = np.zeros(n, np.int64) if stamps is None else np.asarray(stamps, np.int64)
            self._enqueue(t, st, V, ok)
        parts, edge = [], []  # Q_hat of the next rows, in order; rows flushed at a segment end (not evaluated)
        if self._carry is not None:  # a fixed-lag twin replaced by the stand-in: its held rows first
            parts.append(self._carry)
            edge.append(np.ones(len(self._carry), bool))
            self._carry = None
        if len(cuts) and cuts[0] == 0:
            self._flush_into(parts, edge)
            self._reset_segment(t[0])
            n_resets += 1
        for a, b in zip(bounds[:-1], bounds[1:]):
            if a > 0:
                self._flush_into(parts, edge)
                self._reset_segment(t[a])
                n_resets += 1
            q = np.asarray(self.expected.step(t[a:b], X[a:b]), dtype=float)
            parts.append(q)
            edge.append(np.zeros(len(q), bool))
        Q_hat = np.concatenate(parts) if parts else np.zeros(0)
        if not lagged:
            return self._residuals(Q_hat, V, ok, n_resets)
        tq, sq, Vq, okq = self._dequeue(len(Q_hat))
        r = self._residuals(Q_hat, Vq, okq & ~np.concatenate(edge), n_resets)
        return r._replace(t=tq, stamps=sq, V=Vq)

    def drain(self) -> BlockResiduals | None:
        """End of the mission: residuals of the rows a fixed-lag twin still holds (its segment's last samples,
        the batch twin's edge samples: not evaluated); None when nothing waits."""
        if self._queue is None or len(self._queue[0]) == 0:
            return None
        parts, edge = ([self._carry], []) if self._carry is not None else ([], [])
        self._carry = None
        self._flush_into(parts, edge)
        q = np.concatenate(parts) if parts else np.zeros(0)
        n = len(self._queue[0])
        q = np.concatenate([q, np.full(n - len(q), np.nan)])  # rows no model answers for (model switched)
        tq, sq, Vq, okq = self._dequeue(n)
        self._reset_segment(float(tq[-1]))  # a sample pushed after this starts a new segment
        return self._residuals(q, Vq, np.zeros(n, bool), 0)._replace(t=tq, stamps=sq, V=Vq)

    def _hold_back(self) -> None:
        """The running model is about to be reset or replaced: the rows a fixed-lag twin holds take its last
        outputs now (:meth:`block` gives them out first, not evaluated)."""
        waiting = 0 if self._queue is None else len(self._queue[0]) - (0 if self._carry is None else len(self._carry))
        if waiting <= 0:
            return
        parts, edge = [], []
        self._flush_into(parts, edge)
        q = np.concatenate(parts) if parts else np.zeros(0)
        q = np.concatenate([q[:waiting], np.full(max(0, waiting - len(q)), np.nan)])
        self._carry = q if self._carry is None else np.concatenate([self._carry, q])

    def _flush_into(self, parts: list, edge: list) -> None:
        flush = getattr(self.expected, "flush", None)
        if flush is not None:
            q = np.asarray(flush(), dtype=float)
            parts.append(q)
            edge.append(np.ones(len(q), bool))

    def _enqueue(self, t, stamps, V, ok) -> None:
        new = (np.asarray(t, float), stamps, np.asarray(V, float), np.asarray(ok, bool))
        self._queue = new if self._queue is None else tuple(np.concatenate([a, b]) for a, b in zip(self._queue, new))

    def _dequeue(self, k: int):
        q = self._queue
        if k > len(q[0]):
            raise RuntimeError(f"expected-response model gave {k} outputs for {len(q[0])} waiting rows")
        self._queue = tuple(a[k:] for a in q)
        return tuple(a[:k] for a in q)

    def _residuals(self, Q_hat, V, evaluate, n_resets) -> BlockResiduals:
        Q_meas = V[:, 5]
        r_Q = Q_meas - Q_hat
        Q_for_twist = np.where(np.isfinite(Q_meas), Q_meas, Q_hat)
        twist_raw = V[:, 1] - V[:, 0] / self.params.N
        twist = twist_raw - Q_for_twist / self.params.K_out
        r_Q = np.where(evaluate, r_Q, np.nan)
        twist = np.where(evaluate, twist, np.nan)
        twist_raw = np.where(evaluate, twist_raw, np.nan)
        return BlockResiduals(Q_meas, Q_hat, r_Q, Q_for_twist, twist_raw, twist, evaluate, n_resets)

    def one(self, t: float, tm: float, tf: float, wm: float, wf: float, tau: float, Q: float):
        """One valid sample inside a segment -> ``(Q_hat, r_Q, Q_for_twist, twist_raw, twist)``; same arithmetic
        as :meth:`block` (the model must have ``step_one``)."""
        Q_hat = float(self.expected.step_one(t, self._input_one(tm, tf, wm, wf, tau)))
        return self._row(Q_hat, tm, tf, Q, t >= self.settle_until)

    def _input_one(self, tm: float, tf: float, wm: float, wf: float, tau: float) -> np.ndarray:
        """The twin's input row of one sample (the block path's columns; temperature and command held)."""
        x = self._x1
        x[0], x[1], x[2], x[3], x[4] = tm, wm, tau, tf, wf
        x[I_TEMP] = self.temperature
        x[I_REF] = self.theta_ref
        return x

    def _row(self, Q_hat: float, tm: float, tf: float, Q: float, evaluate: bool) -> tuple:
        """``(Q_hat, r_Q, Q_for_twist, twist_raw, twist)`` of one sample whose Q_hat is known: the arithmetic of
        :meth:`_residuals` on scalars."""
        p = self.params
        r_Q = Q - Q_hat  # NaN when Q_red is not measured
        Qt = Q if Q == Q else Q_hat
        tw_raw = tf - tm / p.N
        twist = tw_raw - Qt / p.K_out
        if not evaluate:
            r_Q = twist = tw_raw = math.nan
        return Q_hat, r_Q, Qt, tw_raw, twist

    @property
    def irregular(self) -> bool:
        """Outputs of a replaced / reset model still wait to be given out (the block path handles those)."""
        return self._carry is not None

    def one_delayed(self, t: float, stamp_ns: int, v):
        """One valid sample inside a segment for a fixed-lag twin (the short path): the sample waits, the twin
        steps, and the rows whose output came are returned, oldest first, as ``(t, stamp_ns, values,
        (Q_hat, r_Q, Q_for_twist, twist_raw, twist))``; same arithmetic as :meth:`block`."""
        tm, tf, wm, wf, tau, Q = v
        x = self._input_one(tm, tf, wm, wf, tau)
        self._enqueue(np.array([t]), np.array([stamp_ns], np.int64), np.array([v], float),
                      np.array([t >= self.settle_until]))
        q = self.expected.step(np.array([t]), x[None, :])
        if len(q) == 0:
            return []
        tq, sq, Vq, okq = self._dequeue(len(q))
        out = []
        for i in range(len(q)):
            vk = tuple(Vq[i].tolist())
            out.append((float(tq[i]), int(sq[i]), vk, self._row(float(q[i]), vk[0], vk[1], vk[5], bool(okq[i]))))
        return out

    def _reset_segment(self, t_s: float) -> None:
        self.expected.reset()
        self.settle_until = t_s + self.settle_s
