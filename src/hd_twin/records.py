"""Per-actuator records of the twin state: the residual lines of a channel and the healthy laws of
the stiffness and friction monitors (pure data with their validation; no ROS, no detector logic).

The ground computes them, the twin core validates and keeps them per actuator (:mod:`hd_twin.state`),
the onboard detectors (:mod:`hd_onboard.detectors`) run with them. ``from_dict`` validates a mapping
from a message or file (ValueError naming ``where``), ``to_dict`` is its inverse.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


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
