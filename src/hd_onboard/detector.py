"""Residual evaluation: normalisation, EWMA detector with persistence, fault levels.

Pure numpy, streaming, vectorised over the samples of a block (state carried
between blocks), so the onboard node, the batch evaluation, the ground's
threshold calibration and the tests run the same arithmetic.

Per residual channel c (``Q_red`` in N*m, ``twist`` in rad, ...)::

    z_k = (r_k - mu_c) / sigma_c                      normalised residual [-]
    e_k = (1 - lam) e_{k-1} + lam z_k                 EWMA, lam = dt / tau  [-]
    over_warn_k  = |e_k| > h_warn_c   for >= P consecutive samples
    over_error_k = |e_k| > h_error_c  for >= P consecutive samples

The fault level at sample k is ERROR if ``over_error`` held within the last
``hold_s`` seconds, else WARN if ``over_warn`` did, else OK: a flag is raised
only after P = persistence_s / dt samples above the line (a single spike does
not flag) and stays up at least ``hold_s`` (no chattering). Invalid samples
(NaN residual: sensor NaN, dropout) do not move the EWMA: the filter runs on
the valid samples only and holds its value across the invalid ones.

``mu``, ``sigma``, ``h_warn`` and ``h_error`` are per actuator and per channel
(:class:`ChannelThreshold`); the ground node computes them from healthy
missions (``hd_ground.thresholds``) and pushes them through the twin core.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterable

import numpy as np
from scipy.signal import lfilter

OK, WARN, ERROR, STALE = 0, 1, 2, 3  # diagnostic_msgs/DiagnosticStatus levels
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}


@dataclass
class ChannelThreshold:
    """Normalisation and alarm lines of one residual channel of one actuator.

    ``mu`` and ``sigma`` in the channel's unit (N*m for ``Q_red``, rad for
    ``twist``); ``h_warn`` and ``h_error`` in units of sigma on the EWMA of the
    normalised residual; ``source`` says where they came from.
    """

    mu: float
    sigma: float
    h_warn: float
    h_error: float
    source: str = "default"

    def validate(self, where: str) -> "ChannelThreshold":
        for k in ("mu", "sigma", "h_warn", "h_error"):
            v = getattr(self, k)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"{where}: threshold {k} = {v!r} is not a finite number")
        if self.sigma <= 0:
            raise ValueError(f"{where}: sigma = {self.sigma} must be > 0")
        if not 0 < self.h_warn <= self.h_error:
            raise ValueError(f"{where}: need 0 < h_warn <= h_error, got h_warn={self.h_warn}, h_error={self.h_error}")
        if self.h_error > 1e6:
            raise ValueError(f"{where}: h_error = {self.h_error} is absurd (units of sigma)")
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str) -> "ChannelThreshold":
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
        try:
            t = cls(mu=float(d["mu"]), sigma=float(d["sigma"]), h_warn=float(d["h_warn"]),
                    h_error=float(d["h_error"]), source=str(d.get("source", "update")))
        except KeyError as e:
            raise ValueError(f"{where}: missing threshold key {e}") from None
        except (TypeError, ValueError):
            raise ValueError(f"{where}: threshold values must be numbers, got {d!r}") from None
        return t.validate(where)


def ewma(z: np.ndarray, lam: float, e0: float) -> np.ndarray:
    """EWMA of ``z`` (NaN entries skipped: the output holds across them), starting from ``e0``."""
    z = np.asarray(z, float)
    out = np.empty_like(z)
    valid = np.isfinite(z)
    if not valid.any():
        out.fill(e0)
        return out
    zv = z[valid]
    ev, _ = lfilter([lam], [1.0, -(1.0 - lam)], zv, zi=[(1.0 - lam) * e0])
    # forward fill: every sample takes the value of the last valid sample at or before it
    pos = np.cumsum(valid) - 1  # index in ev of the last valid sample at or before each sample
    out[:] = np.where(pos >= 0, ev[np.clip(pos, 0, None)], e0)
    return out


def run_lengths(b: np.ndarray, carry: int) -> np.ndarray:
    """Length of the run of True ending at each sample (0 where False); ``carry`` continues a run from before."""
    n = len(b)
    idx = np.arange(n)
    last_false = np.maximum.accumulate(np.where(~b, idx, -1))
    run = idx - last_false
    return np.where(last_false < 0, run + carry, run).astype(np.int64)


class ChannelDetector:
    """Streaming EWMA + persistence detector of one residual channel."""

    def __init__(self, name: str, threshold: ChannelThreshold, lam: float, persistence: int):
        self.name = name
        self.threshold = threshold
        self.lam = float(lam)
        self.persistence = max(int(persistence), 1)
        self.reset()

    def reset(self) -> None:
        self.e = 0.0
        self.run_warn = 0
        self.run_error = 0

    def step(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Block of residuals -> (z, e, cond_warn, cond_error) per sample."""
        th = self.threshold
        z = (np.asarray(r, float) - th.mu) / th.sigma
        e = ewma(z, self.lam, self.e)
        if len(e):
            self.e = float(e[-1])
        a = np.abs(e)
        rw = run_lengths(a > th.h_warn, self.run_warn)
        re = run_lengths(a > th.h_error, self.run_error)
        if len(e):
            self.run_warn, self.run_error = int(rw[-1]), int(re[-1])
        return z, e, rw >= self.persistence, re >= self.persistence

    def step_one(self, r: float) -> tuple[float, bool, bool]:
        """One residual (scalar, NaN allowed) -> (e, cond_warn, cond_error); same arithmetic as :meth:`step`."""
        th = self.threshold
        z = (r - th.mu) / th.sigma
        if z == z and z not in (math.inf, -math.inf):
            self.e = self.lam * z + (1.0 - self.lam) * self.e
        a = abs(self.e)
        self.run_warn = self.run_warn + 1 if a > th.h_warn else 0
        self.run_error = self.run_error + 1 if a > th.h_error else 0
        return self.e, self.run_warn >= self.persistence, self.run_error >= self.persistence


class LevelLatch:
    """Turns per-sample WARN/ERROR conditions into levels held for ``hold_s`` seconds."""

    def __init__(self, hold_s: float):
        self.hold_s = float(hold_s)
        self.reset()

    def reset(self) -> None:
        self.last_warn = -math.inf  # s, last time the WARN condition held
        self.last_error = -math.inf

    def step(self, t: np.ndarray, cond_warn: np.ndarray, cond_error: np.ndarray) -> np.ndarray:
        """Level (OK/WARN/ERROR) per sample; ``t`` in s, increasing."""
        lw = np.maximum(np.maximum.accumulate(np.where(cond_warn | cond_error, t, -np.inf)), self.last_warn)
        le = np.maximum(np.maximum.accumulate(np.where(cond_error, t, -np.inf)), self.last_error)
        if len(t):
            self.last_warn, self.last_error = float(lw[-1]), float(le[-1])
        lev = np.full(len(t), OK, dtype=np.int8)
        lev[t - lw < self.hold_s] = WARN
        lev[t - le < self.hold_s] = ERROR
        return lev

    def step_one(self, t: float, cond_warn: bool, cond_error: bool) -> int:
        """Level of one sample at time ``t`` [s]; same arithmetic as :meth:`step`."""
        if cond_warn or cond_error:
            self.last_warn = max(self.last_warn, t)
        if cond_error:
            self.last_error = max(self.last_error, t)
        if t - self.last_error < self.hold_s:
            return ERROR
        if t - self.last_warn < self.hold_s:
            return WARN
        return OK


# ---------------------------------------------------------------------------------------------
# Torsional stiffness monitor
# ---------------------------------------------------------------------------------------------
#: EW moment channels of :class:`StiffnessMonitor`: weight, x, u, y, xx, uu, xu, xy, uy
_SM_NCH = 9


def stiffness_basis(Q: np.ndarray, q1: float, q2: float) -> np.ndarray:
    """Piecewise-linear torsion basis of the output torque ``Q`` [N*m]: (n, 3) columns
    ``Q``, ``sgn(Q) min(|Q|, q1)``, ``sgn(Q) min(|Q|, q2)`` (knots ``q1 < q2`` in N*m).

    A combination ``B c`` is a symmetric piecewise-linear twist law with slope changes at
    ``|Q| = q1, q2`` (the K1/K2/K3 hardening torsion curve of PHYSICS.md, any stiffness
    values) and linear extrapolation beyond ``q2``.
    """
    Q = np.asarray(Q, float)
    s, a = np.sign(Q), np.abs(Q)
    return np.column_stack([Q, s * np.minimum(a, q1), s * np.minimum(a, q2)])


@dataclass
class StiffnessReference:
    """Healthy torsion law of one actuator: ``twist = a + b tanh(omega_m/eps) + g(Q)``.

    ``twist = theta_f - theta_m/N`` [rad]; ``g(Q) = stiffness_basis(Q, q1, q2) @ c`` [rad];
    ``g_scale`` [rad] = std of g over the reference data (normalises the regression);
    ``q_range`` [N*m] the largest |Q| seen; ``compliance`` [rad/(N*m)] the secant compliance
    ``g(q_range)/q_range`` (reported). ``source`` says where it came from.
    """

    a: float
    b: float
    c: tuple
    q1: float
    q2: float
    eps: float
    g_scale: float
    q_range: float
    compliance: float
    n: int
    source: str = "mission warm-up"

    def g(self, Q):
        Q = np.asarray(Q, float)
        c0, c1, c2 = self.c
        s, a = np.sign(Q), np.abs(Q)
        return c0 * Q + c1 * s * np.minimum(a, self.q1) + c2 * s * np.minimum(a, self.q2)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["c"] = list(self.c)
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "stiffness reference") -> "StiffnessReference":
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
        try:
            r = cls(a=float(d["a"]), b=float(d["b"]), c=tuple(float(v) for v in d["c"]), q1=float(d["q1"]),
                    q2=float(d["q2"]), eps=float(d["eps"]), g_scale=float(d["g_scale"]), q_range=float(d["q_range"]),
                    compliance=float(d.get("compliance", math.nan)), n=int(d.get("n", 0)),
                    source=str(d.get("source", "update")))
        except KeyError as e:
            raise ValueError(f"{where}: missing key {e}") from None
        except (TypeError, ValueError):
            raise ValueError(f"{where}: values must be numbers, got {d!r}") from None
        vals = [r.a, r.b, *r.c, r.q1, r.q2, r.eps, r.g_scale, r.q_range]
        if len(r.c) != 3 or not all(math.isfinite(v) for v in vals):
            raise ValueError(f"{where}: need three finite coefficients c and finite a, b, q1, q2, eps, g_scale, q_range")
        if not (0 < r.q1 < r.q2 and r.eps > 0 and r.g_scale > 0 and r.q_range > 0):
            raise ValueError(f"{where}: need 0 < q1 < q2, eps > 0, g_scale > 0, q_range > 0")
        return r


def _group_ls(X: np.ndarray, y: np.ndarray, group: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Least squares ``y = a_g + X coef`` with one intercept per ``group`` label (None: one group).

    Solved by de-meaning ``X`` and ``y`` within each group (Frisch-Waugh: the same ``coef`` as the
    regression with one dummy per group). Returns ``(coef, a)`` with ``a`` the sample-weighted mean
    of the group intercepts (for one group: the ordinary intercept).
    """
    if group is None:
        Xd, yd = X - X.mean(axis=0), y - y.mean()
    else:
        _, code = np.unique(group, return_inverse=True)
        cnt = np.bincount(code).astype(float)
        my = np.bincount(code, weights=y) / cnt
        mX = np.column_stack([np.bincount(code, weights=X[:, j]) / cnt for j in range(X.shape[1])])
        Xd, yd = X - mX[code], y - my[code]
    coef, *_ = np.linalg.lstsq(Xd, yd, rcond=None)
    return coef, float(np.mean(y - X @ coef))


def fit_stiffness_reference(twist: np.ndarray, Q: np.ndarray, omega_m: np.ndarray, eps: float,
                            min_samples: int = 200, source: str = "mission warm-up",
                            group: np.ndarray | None = None) -> StiffnessReference | None:
    """Least-squares healthy torsion law from reference samples (NaN rows ignored).

    ``twist = theta_f - theta_m/N`` [rad], ``Q`` [N*m] output torque (measured, else the
    twin's expected one), ``omega_m`` [rad/s], ``eps`` [rad/s] smoothing of the direction term
    ``tanh(omega_m/eps)`` (lost motion / hysteresis offset). Knots at the 40 % and 75 %
    quantiles of |Q|. ``group`` (optional, one label per sample, e.g. the mission index of
    pooled archived missions): one offset per group (encoders without a common zero across
    missions); ``a`` is then their sample-weighted mean. Returns None when the data do not
    define a law: fewer than ``min_samples`` valid rows, no load variation, or a fitted law that
    is not monotonic (twist must fall or rise with Q on every segment).
    """
    tw, Q, w = (np.asarray(v, float) for v in (twist, Q, omega_m))
    ok = np.isfinite(tw) & np.isfinite(Q) & np.isfinite(w)
    if ok.sum() < min_samples:
        return None
    tw, Q, w = tw[ok], Q[ok], w[ok]
    g = None if group is None else np.asarray(group)[ok]
    aq = np.abs(Q)
    q_range = float(np.max(aq))
    q1, q2 = (float(v) for v in np.quantile(aq, [0.4, 0.75]))
    if not (q_range > 0 and 0 < q1 < q2 < q_range and np.std(Q) > 0.05 * q_range):
        return None
    u = np.tanh(w / eps)
    coef, a0 = _group_ls(np.column_stack([u, stiffness_basis(Q, q1, q2)]), tw, g)
    c = tuple(float(v) for v in coef[1:])
    slopes = np.array([c[0] + c[1] + c[2], c[0] + c[2], c[0]])  # |Q| < q1, q1..q2, > q2
    if not (np.all(slopes > 0) or np.all(slopes < 0)):
        # not a torsion law (too little load range): fall back to one linear compliance
        coef2, a0 = _group_ls(np.column_stack([u, Q]), tw, g)
        if coef2[1] == 0:
            return None
        coef = np.array([coef2[0], coef2[1]])
        c = (float(coef2[1]), 0.0, 0.0)
    ref = StiffnessReference(a0, float(coef[0]), c, q1, q2, float(eps), 1.0, q_range, 0.0, int(len(Q)), source)
    g = ref.g(Q)
    gs = float(np.std(g))
    if not gs > 0:
        return None
    ref.g_scale = gs
    ref.compliance = float(ref.g(np.array([q_range]))[0] / q_range)
    return ref


class _EWMonitor:
    """What the stiffness and friction monitors share: exponentially weighted regression moments
    (forgetting time ``tau_s`` [s]), the persistence runs of their WARN/ERROR lines and the level.

    A subclass sets ``ref`` and implements its moment inputs and solution; ``m`` holds the
    moments carried between blocks.
    """

    n_moments = 0

    def __init__(self, tau_s: float, persistence: int, fs: float):
        self.tau_s = float(tau_s)
        self.persistence = max(1, int(persistence))
        self.ref = None
        self.set_rate(fs)
        self.reset()

    def set_rate(self, fs: float) -> None:
        self.lam = min(1.0, 1.0 / (self.tau_s * fs))

    def reset(self) -> None:
        self.m = np.zeros(self.n_moments)
        self.run_warn = 0
        self.run_error = 0
        self.n_eval = 0

    def _ew_moments(self, X: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Moments after every sample of a block (rows of ``X`` where ``valid``; an invalid sample
        repeats the last moments) and carry the last ones to the next block."""
        n = len(valid)
        M = np.empty((n, self.n_moments))
        lam = self.lam
        if valid.any():
            Mv, _ = lfilter([lam], [1.0, -(1.0 - lam)], X[valid], axis=0, zi=((1.0 - lam) * self.m)[None, :])
            pos = np.cumsum(valid) - 1
            M[:] = np.where((pos >= 0)[:, None], Mv[np.clip(pos, 0, None)], self.m[None, :])
            self.m = Mv[-1].copy()
        else:
            M[:] = self.m[None, :]
        return M

    def _ew_update(self, x: tuple) -> list[float]:
        """Scalar path: fold one sample's moment inputs ``x`` into ``m`` (same recursion as the block;
        plain floats: numpy on a 5-9 element vector costs more than the arithmetic)."""
        lam, k = self.lam, 1.0 - self.lam
        new = [k * a + lam * b for a, b in zip(self.m.tolist(), x)]
        self.m[:] = new
        return new

    def _runs(self, ok: np.ndarray, v: np.ndarray, warn: float, error: float):
        """Block persistence: (cond_warn, cond_error) per sample for the estimate ``v`` where ``ok``."""
        rw = run_lengths(ok & (v > warn), self.run_warn)
        re = run_lengths(ok & (v > error), self.run_error)
        self.run_warn, self.run_error = int(rw[-1]), int(re[-1])
        self.n_eval += int(ok.sum())
        return rw >= self.persistence, re >= self.persistence

    def _runs_one(self, v: float, warn: float, error: float) -> tuple[bool, bool]:
        """Scalar persistence for one evaluable estimate ``v``."""
        self.n_eval += 1
        self.run_warn = self.run_warn + 1 if v > warn else 0
        self.run_error = self.run_error + 1 if v > error else 0
        return self.run_warn >= self.persistence, self.run_error >= self.persistence

    def _not_evaluable(self) -> tuple[float, bool, bool]:
        self.run_warn = self.run_error = 0
        return math.nan, False, False

    def level(self) -> int:
        """Level of the current estimate (persistence applied): OK / WARN / ERROR."""
        if self.run_error >= self.persistence:
            return ERROR
        if self.run_warn >= self.persistence:
            return WARN
        return OK


class StiffnessMonitor(_EWMonitor):
    """Streaming torsional-stiffness estimator and flag (one actuator).

    After a reference law :class:`StiffnessReference` is known (learnt on the mission's
    warm-up by the onboard core, or given by the ground), every valid sample updates
    exponentially weighted (time constant ``tau_s``) moments of

        x = g(Q) / g_scale,  u = tanh(omega_m / eps),  y = (twist - a) / g_scale

    and the weighted least-squares regression ``y = alpha + beta u + s x`` gives the
    **compliance ratio** ``s`` (1 when healthy: twist per torque as in the reference;
    a flexspline that lost stiffness twists more). The reported **stiffness loss** is
    ``1 - 1/s`` (fraction of the effective torsional stiffness lost, referred to the
    whole output path). It is evaluated only on *loaded* windows: the weighted std of x
    must reach ``min_excitation`` (fraction of the reference's load variation) and x and u
    must not be collinear; elsewhere it is NaN and the flag's persistence run restarts.

    WARN when the loss exceeds ``loss_warn``, ERROR above ``loss_error``, each for
    ``persistence`` consecutive evaluable samples. Block (:meth:`step`) and scalar
    (:meth:`step_one`) paths give the same numbers.
    """

    n_moments = _SM_NCH

    def __init__(self, tau_s: float = 2.0, loss_warn: float = 0.08, loss_error: float = 0.2,
                 persistence: int = 500, min_excitation: float = 0.5, fs: float = 1000.0):
        self.loss_warn, self.loss_error = float(loss_warn), float(loss_error)
        self.min_excitation = float(min_excitation)
        super().__init__(tau_s, persistence, fs)
        self.ref: StiffnessReference | None = None

    def reset(self) -> None:
        super().reset()
        self.loss = math.nan  # last evaluable estimate
        self.s = math.nan

    # --- arithmetic shared by the two paths
    def _moments_inputs(self, twist, Q, omega_m):
        r = self.ref
        x = r.g(Q) / r.g_scale
        u = np.tanh(np.asarray(omega_m, float) / r.eps)
        y = (np.asarray(twist, float) - r.a) / r.g_scale
        return np.column_stack([np.ones(len(x)), x, u, y, x * x, u * u, x * u, x * y, u * y])

    def _solve(self, m):
        """Moments (..., 9) -> (s, ok) vectorised."""
        W = m[..., 0]
        Wd = np.where(W > 0, W, 1.0)
        mx, mu_, my = m[..., 1] / Wd, m[..., 2] / Wd, m[..., 3] / Wd
        vxx = m[..., 4] / Wd - mx * mx
        vuu = m[..., 5] / Wd - mu_ * mu_
        vxu = m[..., 6] / Wd - mx * mu_
        vxy = m[..., 7] / Wd - mx * my
        vuy = m[..., 8] / Wd - mu_ * my
        det = vuu * vxx - vxu * vxu
        two = vuu > 1e-3
        s2 = (vuu * vxy - vxu * vuy) / np.where(det > 0, det, 1.0)
        s1 = vxy / np.where(vxx > 0, vxx, 1.0)
        s = np.where(two, s2, s1)
        ok = (W > 0.6) & (vxx >= self.min_excitation ** 2) & (~two | (det >= 0.2 * vuu * vxx)) & (s > 0)
        return s, ok

    def step(self, twist: np.ndarray, Q: np.ndarray, omega_m: np.ndarray, valid: np.ndarray):
        """Block -> (loss per sample, NaN where not evaluable; cond_warn; cond_error)."""
        n = len(twist)
        if self.ref is None or n == 0:
            z = np.zeros(n, bool)
            return np.full(n, np.nan), z, z
        X = self._moments_inputs(twist, Q, omega_m)
        valid = np.asarray(valid, bool) & np.isfinite(X).all(axis=1)
        s, ok = self._solve(self._ew_moments(X, valid))
        ok &= valid
        loss = np.where(ok, 1.0 - 1.0 / np.where(ok, s, 1.0), np.nan)
        cw, ce = self._runs(ok, loss, self.loss_warn, self.loss_error)
        if ok.any():
            k = int(np.flatnonzero(ok)[-1])
            self.loss, self.s = float(loss[k]), float(s[k])
        return loss, cw, ce

    def step_one(self, twist: float, Q: float, omega_m: float) -> tuple[float, bool, bool]:
        """One sample (NaN allowed) -> (loss or NaN, cond_warn, cond_error); same arithmetic as :meth:`step`."""
        r = self.ref
        if r is None:
            return math.nan, False, False
        aq = abs(Q)
        sg = (Q > 0) - (Q < 0)
        c0, c1, c2 = r.c
        x = (c0 * Q + c1 * sg * min(aq, r.q1) + c2 * sg * min(aq, r.q2)) / r.g_scale
        u = math.tanh(omega_m / r.eps)
        y = (twist - r.a) / r.g_scale
        if not (x == x and y == y and u == u and abs(x) != math.inf and abs(y) != math.inf):
            return self._not_evaluable()
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = self._ew_update((1.0, x, u, y, x * x, u * u, x * u, x * y, u * y))
        mx, mu_, my = m1 / m0, m2 / m0, m3 / m0
        vxx = m4 / m0 - mx * mx
        vuu = m5 / m0 - mu_ * mu_
        vxu = m6 / m0 - mx * mu_
        vxy = m7 / m0 - mx * my
        vuy = m8 / m0 - mu_ * my
        det = vuu * vxx - vxu * vxu
        if vuu > 1e-3:
            s = (vuu * vxy - vxu * vuy) / (det if det > 0 else 1.0)
            ok = det >= 0.2 * vuu * vxx
        else:
            s = vxy / (vxx if vxx > 0 else 1.0)
            ok = True
        ok = ok and m0 > 0.6 and vxx >= self.min_excitation ** 2 and s > 0
        if not ok:
            return self._not_evaluable()
        loss = 1.0 - 1.0 / s
        self.loss, self.s = loss, s
        return (loss, *self._runs_one(loss, self.loss_warn, self.loss_error))


def persistent_peak(a: np.ndarray, p: int) -> float:
    """max over k of min(a[k:k+p]) (NaN ignored: they break the run)."""
    a = np.where(np.isfinite(a), a, -np.inf)
    if len(a) == 0:
        return 0.0
    p = max(1, min(int(p), len(a)))
    if p == 1:
        v = float(np.max(a))
    else:
        v = float(np.lib.stride_tricks.sliding_window_view(a, p).min(axis=1).max())
    return v if np.isfinite(v) else 0.0


def robust_threshold(segments: Iterable[np.ndarray], *, fs: float, ewma_tau_s: float, persistence_s: float,
                     warn_margin: float, error_margin: float, min_h_warn: float, min_h_error: float,
                     sigma_floor: float = 0.0, source: str, min_samples: int = 200,
                     where: str = "thresholds") -> ChannelThreshold | None:
    """Lines of one channel from healthy residual ``segments`` (each 1-D, NaN allowed): the one
    robust-threshold function, used by the onboard self-calibration (one warm-up segment, with a
    scale floor; :func:`calibrate_channel`) and the ground (healthy missions;
    ``hd_ground.thresholds.channel_threshold``).

    ``mu`` = median, ``sigma = max(1.4826 MAD, sigma_floor)`` (channel unit) over all finite
    samples, then per segment the persistent peak (:func:`persistent_peak` over
    ``persistence_s``) of |EWMA| of ``(r - mu)/sigma`` after one time constant ``ewma_tau_s``
    (the EWMA as onboard, :func:`ewma`), the largest over segments; ``h_warn = max(min_h_warn,
    warn_margin peak)``, ``h_error = max(min_h_error, error_margin peak, 1.5 h_warn)``.
    ``fs`` [Hz] residual sample rate. None with fewer than ``min_samples`` finite values;
    ValueError naming ``where`` for a non-positive ``fs``.
    """
    segs = [np.asarray(s, dtype=float) for s in segments]
    allr = np.concatenate(segs) if segs else np.empty(0)
    fin = allr[np.isfinite(allr)]
    if len(fin) < min_samples:
        return None
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"{where}: sample rate {fs!r} Hz is not positive")
    mu = float(np.median(fin))
    sigma = float(1.4826 * np.median(np.abs(fin - mu)))
    if not sigma > 0:
        sigma = float(np.std(fin)) or 1e-12
    if math.isfinite(sigma_floor) and sigma_floor > sigma:
        sigma = float(sigma_floor)
        source += ", sigma floor"
    lam = min(1.0, 1.0 / (ewma_tau_s * fs))
    p = max(1, int(round(persistence_s * fs)))
    peak = 0.0
    for s in segs:
        if np.isfinite(s).sum() < 2:
            continue
        e = ewma((s - mu) / sigma, lam, 0.0)
        e = np.where(np.isfinite(s), np.abs(e), np.nan)
        # skip the EWMA start-up (one time constant): it starts from 0, not from the data
        e[: int(ewma_tau_s * fs)] = np.nan
        peak = max(peak, persistent_peak(e, p))
    h_warn = max(min_h_warn, warn_margin * peak)
    h_error = max(min_h_error, error_margin * peak, 1.5 * h_warn)
    return ChannelThreshold(mu, sigma, float(h_warn), float(h_error), source).validate(where)


def calibrate_channel(r: np.ndarray, *, fs: float, ewma_tau_s: float, persistence_s: float, warn_margin: float,
                      error_margin: float, min_h_warn: float, min_h_error: float, sigma_floor: float = 0.0,
                      source: str = "self-calibrated (mission warm-up)", min_samples: int = 200) -> ChannelThreshold | None:
    """Lines of one channel from one healthy residual segment ``r`` (NaN allowed), with a scale floor:
    :func:`robust_threshold` on ``[r]``. The floor is what a short warm-up cannot show: the twin's
    error on manoeuvres the warm-up did not contain (the onboard core sets it from the load range
    seen, see ``OnboardConfig.sigma_floor_rel``). None with fewer than ``min_samples`` finite values.
    """
    return robust_threshold([r], fs=fs, ewma_tau_s=ewma_tau_s, persistence_s=persistence_s,
                            warn_margin=warn_margin, error_margin=error_margin, min_h_warn=min_h_warn,
                            min_h_error=min_h_error, sigma_floor=sigma_floor, source=source,
                            min_samples=min_samples, where="self-calibration")


# ---------------------------------------------------------------------------------------------
# Friction (lubrication) monitor: the direction-odd part of the output-torque residual
# ---------------------------------------------------------------------------------------------
#: EW moment channels of :class:`FrictionMonitor`: weight, u, y, uu, uy
_FM_NCH = 5


@dataclass
class FrictionReference:
    """Healthy friction mismatch of one actuator: ``r_Q = a + b u``, ``u = tanh(omega_m/eps)``.

    ``r_Q`` [N*m] is the output-torque residual (measured - expected Q_red); the twin's
    declared friction is already in the expected torque, so ``b`` [N*m] is this unit's
    output-referred Coulomb-like friction not explained by the twin (negative: more
    friction than the twin's). ``a`` [N*m] offset (sensor zero, load-model bias);
    ``eps`` [rad/s] width of the regularised sign (the twin's ``eps_omega``);
    ``scale`` [N*m] the friction unit the excess is expressed in (the twin's nominal
    output-referred Coulomb torque ``N T_C``); ``n`` samples it was fitted on.
    """

    a: float
    b: float
    eps: float
    scale: float
    n: int
    source: str = "mission warm-up"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str = "friction reference") -> "FrictionReference":
        """Validated reference from a mapping (twin state / ground update); ValueError naming ``where``."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
        try:
            r = cls(a=float(d["a"]), b=float(d["b"]), eps=float(d["eps"]), scale=float(d["scale"]),
                    n=int(d.get("n", 0)), source=str(d.get("source", "update")))
        except KeyError as e:
            raise ValueError(f"{where}: missing key {e}") from None
        except (TypeError, ValueError):
            raise ValueError(f"{where}: values must be numbers, got {d!r}") from None
        if not all(math.isfinite(v) for v in (r.a, r.b, r.eps, r.scale)):
            raise ValueError(f"{where}: a, b, eps, scale must be finite, got {d!r}")
        if not (r.eps > 0 and r.scale > 0):
            raise ValueError(f"{where}: need eps > 0 and scale > 0, got eps={r.eps}, scale={r.scale}")
        if abs(r.b) > 1e3 * r.scale:
            raise ValueError(f"{where}: |b| = {abs(r.b):g} N*m is absurd against scale {r.scale:g} N*m")
        return r


def fit_friction_reference(r_Q: np.ndarray, omega_m: np.ndarray, eps: float, scale: float, min_samples: int = 200,
                           min_var_u: float = 0.05, source: str = "mission warm-up",
                           group: np.ndarray | None = None) -> FrictionReference | None:
    """Least-squares healthy law ``r_Q = a + b tanh(omega_m/eps)`` (NaN rows ignored).

    ``r_Q`` [N*m], ``omega_m`` [rad/s], ``eps`` [rad/s], ``scale`` [N*m] > 0. ``group``
    (optional, one label per sample, e.g. the mission of pooled archived missions): one offset
    ``a`` per group (torque-sensor zero drift between missions), ``a`` then their mean. None when
    the data do not define it: fewer than ``min_samples`` valid rows or too little motion in
    both directions (variance of u below ``min_var_u``).
    """
    r, w = np.asarray(r_Q, float), np.asarray(omega_m, float)
    ok = np.isfinite(r) & np.isfinite(w)
    if ok.sum() < min_samples or not (math.isfinite(scale) and scale > 0 and eps > 0):
        return None
    r, u = r[ok], np.tanh(w[ok] / eps)
    if np.var(u) < min_var_u:
        return None
    coef, a0 = _group_ls(u[:, None], r, None if group is None else np.asarray(group)[ok])
    return FrictionReference(a0, float(coef[0]), float(eps), float(scale), int(len(u)), source)


class FrictionMonitor(_EWMonitor):
    """Streaming friction estimator and flag (lubrication loss, one actuator).

    Friction opposes motion, so more friction (lost or degraded lubricant: Coulomb,
    viscous and mesh-flank terms all rise) lowers the measured output torque in the
    direction of motion for the same motor torque: the residual ``r_Q = Q_red - Q_red_hat``
    moves by ``-dL u`` with ``u = tanh(omega_m/eps)`` and ``dL`` [N*m] the extra
    output-referred friction torque. An EWMA of ``r_Q`` alone averages that out over a
    bidirectional manoeuvre; this monitor instead keeps exponentially weighted (time
    constant ``tau_s``) moments of ``u`` and ``y = r_Q - a`` and solves the weighted
    regression ``y = alpha + beta u``. The **friction excess** is

        x = -(beta - b_ref) / scale    [-]

    (extra friction torque in units of the twin's nominal output-referred Coulomb torque;
    0 when healthy, about ``severity * (true friction) / scale`` after a lubrication loss
    that multiplies friction by 1 + severity). It is evaluated only while the window holds
    motion in both directions (weighted variance of u >= ``min_var_u``); elsewhere NaN and
    the persistence run restarts. WARN above ``excess_warn``, ERROR above ``excess_error``,
    each for ``persistence`` consecutive evaluable samples. Needs the measured ``Q_red``:
    without it every sample is NaN (the monitor stays silent). Block (:meth:`step`) and
    scalar (:meth:`step_one`) paths give the same numbers.
    """

    n_moments = _FM_NCH

    def __init__(self, tau_s: float = 2.0, excess_warn: float = 2.5, excess_error: float = 4.0,
                 persistence: int = 250, min_var_u: float = 0.05, fs: float = 1000.0):
        self.excess_warn, self.excess_error = float(excess_warn), float(excess_error)
        self.min_var_u = float(min_var_u)
        super().__init__(tau_s, persistence, fs)
        self.ref: FrictionReference | None = None

    def reset(self) -> None:
        super().reset()
        self.excess = math.nan  # last evaluable estimate

    def _solve(self, m):
        """Moments (..., 5) -> (excess, ok), vectorised."""
        r = self.ref
        W = m[..., 0]
        Wd = np.where(W > 0, W, 1.0)
        mu_, my = m[..., 1] / Wd, m[..., 2] / Wd
        vuu = m[..., 3] / Wd - mu_ * mu_
        vuy = m[..., 4] / Wd - mu_ * my
        beta = vuy / np.where(vuu > 0, vuu, 1.0)
        ok = (W > 0.6) & (vuu >= self.min_var_u)
        return -(beta - r.b) / r.scale, ok

    def step(self, r_Q: np.ndarray, omega_m: np.ndarray, valid: np.ndarray):
        """Block -> (excess per sample, NaN where not evaluable; cond_warn; cond_error)."""
        n = len(r_Q)
        z = np.zeros(n, bool)
        if self.ref is None or n == 0:
            return np.full(n, np.nan), z, z
        r = self.ref
        u = np.tanh(np.asarray(omega_m, float) / r.eps)
        y = np.asarray(r_Q, float) - r.a
        valid = np.asarray(valid, bool) & np.isfinite(u) & np.isfinite(y)
        X = np.column_stack([np.ones(n), u, y, u * u, u * y])
        x, ok = self._solve(self._ew_moments(X, valid))
        ok &= valid
        x = np.where(ok, x, np.nan)
        cw, ce = self._runs(ok, x, self.excess_warn, self.excess_error)
        if ok.any():
            self.excess = float(x[int(np.flatnonzero(ok)[-1])])
        return x, cw, ce

    def step_one(self, r_Q: float, omega_m: float) -> tuple[float, bool, bool]:
        """One sample (NaN allowed) -> (excess or NaN, cond_warn, cond_error); same arithmetic as :meth:`step`."""
        r = self.ref
        if r is None:
            return math.nan, False, False
        u = math.tanh(omega_m / r.eps)
        y = r_Q - r.a
        if not (u == u and y == y and abs(y) != math.inf):
            return self._not_evaluable()
        m0, m1, m2, m3, m4 = self._ew_update((1.0, u, y, u * u, u * y))
        mu_, my = m1 / m0, m2 / m0
        vuu = m3 / m0 - mu_ * mu_
        vuy = m4 / m0 - mu_ * my
        if not (m0 > 0.6 and vuu >= self.min_var_u):
            return self._not_evaluable()
        x = -(vuy / vuu - r.b) / r.scale
        self.excess = x
        return (x, *self._runs_one(x, self.excess_warn, self.excess_error))
