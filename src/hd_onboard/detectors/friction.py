"""Friction (lubrication) monitor: the direction-odd part of the output-torque residual. The healthy
mismatch (:class:`FrictionReference`, fitted by :func:`fit_friction_reference`) and the streaming
friction-excess estimator and flag (:class:`FrictionMonitor`)."""

from __future__ import annotations

import math

import numpy as np

from hd_onboard.detectors.regression import EWMonitor, group_ls
from hd_twin.records import FrictionReference  # noqa: F401 - the twin state's record, defined there

#: EW moment channels of :class:`FrictionMonitor`: weight, u, y, uu, uy
_FM_NCH = 5


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
    coef, a0 = group_ls(u[:, None], r, None if group is None else np.asarray(group)[ok])
    return FrictionReference(a0, float(coef[0]), float(eps), float(scale), int(len(u)), source)


class FrictionMonitor(EWMonitor):
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
