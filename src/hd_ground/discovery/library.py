"""Candidate-effect library for discovery: physically meaningful additive terms.

Each :class:`Candidate` is one way an effect the twin may lack can appear in
the model of a measured signal: a group of basis functions (``hd_twin.terms``
specs) with its canonical PHYSICS.md section 7 name, the variable it depends
on, its harmonic order, a formula and a rule turning fitted coefficients into
physically named parameters. Candidates that explain the *same* structure in
different ways (e.g. the order-2 ripple of ``theta_m`` as a plain torque, as a
direction-dependent friction or as a current-proportional ripple; the Stribeck
term at different characteristic speeds) share a ``family``: selection keeps
at most one variant per family, the one that generalises best.

The registry is extensible: ``register_candidate_builder(fn)`` adds a function
``fn(ctx) -> list[Candidate]`` that is called with the :class:`LibraryContext`
of the data at hand.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hd_twin.terms import harmonic_amplitude_phase, make_term, sin_cos_pair


@dataclass
class Candidate:
    """One candidate term group."""

    name: str  # canonical catalog name or "unknown"
    family: str  # alternatives of one family are mutually exclusive
    variable: str | None
    order: float | None
    basis: list[dict]
    form: str  # formula with symbolic parameters
    to_parameters: Callable[[np.ndarray], dict] = field(repr=False, default=lambda c: {})
    requires: tuple[str, ...] = ()
    nonlinear: dict = field(default_factory=dict)  # fixed shape parameters (e.g. omega_s, delta)
    positive: bool = False  # physics requires a positive coefficient (e.g. T_S - T_C > 0)

    def term(self, signal: str, coef) -> dict:
        """The fitted candidate as an ``hd_twin.terms`` term dict."""
        coef = np.asarray(coef, float)
        params = dict(self.nonlinear)
        params.update(self.to_parameters(coef))
        return make_term(
            self.name, signal, self.basis, coef, variable=self.variable, order=self.order, form=self.form,
            parameters=params,
        )


@dataclass
class LibraryContext:
    """What the library needs to know about the data (all from measured signals, never /sim)."""

    target: str  # "tau_m" or "Q_red"
    available: set[str]  # signal names with finite, varying data
    omega_scale: float  # rad/s, robust |omega_m| scale (q90)
    omega_low: float  # rad/s, robust low-speed scale (q10 of |omega_m| where moving)
    sgn_eps: float  # rad/s, width of the smoothed sign
    t_ref: float  # degC, reference temperature (median of the fit data)
    orders: dict[str, list[float]] = field(default_factory=dict)  # variable -> harmonic orders to try
    declared: set[str] = field(default_factory=set)  # the twin's declared effects (never re-proposed)
    excluded: set[str] = field(default_factory=set)  # names/variables that cannot be identified on these data
    n_pole_pairs_hint: int | None = None


_BUILDERS: list[Callable[[LibraryContext], list[Candidate]]] = []


def register_candidate_builder(fn: Callable[[LibraryContext], list[Candidate]]):
    """Add a candidate builder (decorator-friendly)."""
    _BUILDERS.append(fn)
    return fn


def build_candidates(ctx: LibraryContext) -> list[Candidate]:
    """All candidates for ``ctx``, minus declared effects, unidentifiable ones and those lacking signals."""
    out = []
    for b in _BUILDERS:
        for c in b(ctx):
            if c.name in ctx.declared and c.name != "unknown":
                continue
            if c.name in ctx.excluded or (c.variable in ctx.excluded):
                continue
            if any(r not in ctx.available for r in c.requires):
                continue
            out.append(c)
    return out


def _sgn(ctx, var="omega_m"):
    return {"op": "sgn", "var": var, "eps": ctx.sgn_eps}


def _harm_params(prefix: str, k, scale: float = 1.0):
    def f(c):
        a, psi = harmonic_amplitude_phase(c[0], c[1])
        return {f"{prefix}_{_kstr(k)}": a * scale, f"phase_{_kstr(k)}": psi}

    return f


def _kstr(k) -> str:
    return str(int(k)) if float(k).is_integer() else f"{k:g}"


# ---------------------------------------------------------------------------
# friction-type effects of the motor-torque model
# ---------------------------------------------------------------------------


@register_candidate_builder
def friction_candidates(ctx: LibraryContext) -> list[Candidate]:
    if ctx.target != "tau_m":
        return []
    out: list[Candidate] = []
    # Stribeck: grid over the characteristic speed and the shape exponent.
    lo = max(ctx.omega_low * 0.3, 1e-3)
    hi = max(ctx.omega_scale * 0.6, lo * 2)
    for w_s in np.geomspace(lo, hi, 16):
        for delta in (0.5, 1.0, 1.5, 2.0):
            out.append(Candidate(
                "stribeck_friction", "stribeck", "omega_m", None,
                [{"op": "stribeck", "var": "omega_m", "v_s": float(w_s), "delta": delta, "eps": ctx.sgn_eps}],
                "(T_S - T_C) exp(-(|omega_m|/omega_s)^delta) sgn(omega_m)",
                lambda c: {"T_S_minus_T_C": float(c[0])},
                requires=("omega_m",), nonlinear={"omega_s": float(w_s), "delta": delta}, positive=True,
            ))
    # Temperature-dependent friction: viscous and Coulomb coefficients drifting with T.
    tref = {"op": "offset", "var": "temperature", "ref": ctx.t_ref}
    out.append(Candidate(
        "temperature_dependent_friction", "temperature", "temperature", None,
        [{"op": "prod", "factors": [{"op": "var", "var": "omega_m"}, tref]},
         {"op": "prod", "factors": [_sgn(ctx), tref]}],
        "(db/dT omega_m + dT_C/dT sgn(omega_m)) (T - T_ref)",
        lambda c: {"db_dT": float(c[0]), "dT_C_dT": float(c[1])},
        requires=("omega_m", "temperature"), nonlinear={"T_ref": ctx.t_ref},
    ))
    # Load-dependent (Coulomb share proportional to the transmitted torque).
    out.append(Candidate(
        "load_dependent_friction", "load", "Q_red", None,
        [{"op": "prod", "factors": [{"op": "abs", "var": "Q_red"}, _sgn(ctx)]}],
        "c_L |Q_red| sgn(omega_m)",
        lambda c: {"c_L": float(c[0])},
        requires=("omega_m", "Q_red"),
    ))
    # Velocity-squared drag (windage, churning): outside the catalog.
    out.append(Candidate(
        "unknown", "drag", "omega_m", None,
        [{"op": "prod", "factors": [{"op": "var", "var": "omega_m"}, {"op": "abs", "var": "omega_m"}]}],
        "d omega_m |omega_m|",
        lambda c: {"d": float(c[0])},
        requires=("omega_m",),
    ))
    # Constant bias (sensor offset, gravity on the output): outside the catalog.
    out.append(Candidate(
        "unknown", "bias", None, None, [{"op": "const"}], "c_0", lambda c: {"c_0": float(c[0])},
    ))
    return out


# ---------------------------------------------------------------------------
# position-periodic effects: harmonics of an angle at the orders to try
# ---------------------------------------------------------------------------


def _periodic_name(target: str, var: str, k: float, variant: str) -> str:
    integer = float(k).is_integer()
    if not integer:
        return "unknown"
    if variant == "sgn":
        return "position_periodic_friction"
    if variant == "iq":
        # torque ripple of a PMSM sits at multiples of 6 electrical orders (6 p k mechanical)
        return "current_ripple" if int(k) % 6 == 0 else "unknown"
    if variant == "twist":
        return "position_dependent_stiffness" if var == "theta_m" else "unknown"
    # direction-independent
    if target == "Q_red" and var == "theta_m":
        return "kinematic_error_harmonic"
    if var == "theta_m" and k > 4:
        return "cogging_torque"
    return "position_periodic_torque"


@register_candidate_builder
def periodic_candidates(ctx: LibraryContext) -> list[Candidate]:
    out: list[Candidate] = []
    for var, orders in ctx.orders.items():
        if var not in ctx.available:
            continue
        for k in orders:
            ks = _kstr(k)
            fam = f"{var}:{ks}"
            variants = [("plain", None, f"A_{ks} sin({ks} {var} + psi_{ks})", "A")]
            if ctx.target == "tau_m" and "omega_m" in ctx.available:
                variants.append(("sgn", _sgn(ctx), f"F_{ks} sin({ks} {var} + rho_{ks}) sgn(omega_m)", "F"))
            if ctx.target == "tau_m" and "i_q" in ctx.available and var == "theta_m":
                variants.append(("iq", {"op": "var", "var": "i_q"}, f"k_t r_{ks} i_q sin({ks} {var} + psi_{ks})", "k_t_r"))
            if ctx.target == "Q_red" and "windup" in ctx.available and var == "theta_m":
                variants.append(("twist", {"op": "var", "var": "windup"},
                                 f"K eps_{ks} w cos({ks} {var} + psi_{ks}), w = theta_m/N - theta_f", "K_eps"))
            for variant, times, form, pname in variants:
                out.append(Candidate(
                    _periodic_name(ctx.target, var, k, variant), fam, var, float(k),
                    sin_cos_pair(var, float(k), times), form, _harm_params(pname, k),
                    requires=tuple({var} | ({times["var"]} if times and "var" in times else set())),
                ))
            if ctx.target == "Q_red" and "windup" in ctx.available and var == "theta_m" and float(k).is_integer():
                # load-dependent amplitude of the same ripple (e.g. the KE's A_k(1 + a_T |T|/T_rated)): an
                # additional group in its own family, so that it can join the plain ripple, never replace it
                out.append(Candidate(
                    _periodic_name(ctx.target, var, k, "plain"), f"{fam}:load", var, float(k),
                    sin_cos_pair(var, float(k), {"op": "abs", "var": "windup"}),
                    f"K a_{ks} |w| sin({ks} {var} + psi_{ks}), w = theta_m/N - theta_f (load-dependent amplitude)",
                    _harm_params("K_a", k), requires=(var, "windup"),
                ))
    return out


# ---------------------------------------------------------------------------
# transmission (output-torque) effects
# ---------------------------------------------------------------------------


@register_candidate_builder
def transmission_candidates(ctx: LibraryContext) -> list[Candidate]:
    if ctx.target != "Q_red":
        return []
    return [
        Candidate("nonlinear_stiffness", "stiffness", "windup", None,
                  [{"op": "pow", "var": "windup", "p": 3.0}], "k3 w^3, w = theta_m/N - theta_f",
                  lambda c: {"k3": float(c[0])}, requires=("windup",)),
        Candidate("hysteresis", "hysteresis", "windup", None,
                  [{"op": "sgn", "var": "windup_dot", "eps": 0.0}], "T_h sgn(w'), w = theta_m/N - theta_f",
                  lambda c: {"T_h": float(c[0])}, requires=("windup_dot",),
                  # a hysteresis loop dissipates: the loop integral of Q_red dw = T_h * total |dw| > 0
                  positive=True),
        Candidate("unknown", "bias", None, None, [{"op": "const"}], "c_0", lambda c: {"c_0": float(c[0])}),
    ]


def catalog_orders(var: str) -> list[float]:
    """Low orders always worth trying for an angle (PHYSICS.md 2.4, 2.5, 5)."""
    return [1.0, 2.0, 4.0] if var == "theta_m" else [1.0, 2.0]


def merge_orders(*lists: list[float], tol: float = 1e-6) -> list[float]:
    out: list[float] = []
    for lst in lists:
        for k in lst:
            if not any(abs(k - o) < tol for o in out) and k > 0 and math.isfinite(k):
                out.append(float(k))
    return sorted(out)
