"""Torsional stiffness monitor: the healthy torsion law (:class:`StiffnessReference`, fitted by
:func:`fit_stiffness_reference`) and the streaming compliance-ratio estimator and flag
(:class:`StiffnessMonitor`)."""

from __future__ import annotations

import math

import numpy as np

from hd_onboard.detectors.regression import EWMonitor, group_ls
from hd_twin.records import StiffnessReference  # noqa: F401 - the twin state's record, defined there

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
    coef, a0 = group_ls(np.column_stack([u, stiffness_basis(Q, q1, q2)]), tw, g)
    c = tuple(float(v) for v in coef[1:])
    slopes = np.array([c[0] + c[1] + c[2], c[0] + c[2], c[0]])  # |Q| < q1, q1..q2, > q2
    if not (np.all(slopes > 0) or np.all(slopes < 0)):
        # not a torsion law (too little load range): fall back to one linear compliance
        coef2, a0 = group_ls(np.column_stack([u, Q]), tw, g)
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


class StiffnessMonitor(EWMonitor):
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
