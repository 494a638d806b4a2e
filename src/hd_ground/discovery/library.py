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

from hd_twin.identify import Shape
from hd_twin.terms import harmonic_amplitude_phase, make_term, sin_cos_pair


#: Name prefix of a pre-sliding state column (``hd_twin.identify.presliding_state`` of a measured angle or
#: twist at a distance): computed by discovery from the time-ordered series, not a measured signal.
STATE_PREFIX = "presliding:"


def measured_signal(var: str) -> str:
    """The logged signal a column is computed from: ``var`` itself, or the angle / twist under a pre-sliding state
    column (``presliding:theta_m:...`` -> ``theta_m``). A candidate requires the signal, never the derived column:
    the state is made by discovery, so it is in no bag's list of available signals."""
    return var.split(":")[1] if var.startswith(STATE_PREFIX) else var


def state_var(var: str, distance: float) -> str:
    """Column name of the pre-sliding state of ``var`` at ``distance`` (same unit as ``var``)."""
    return f"{STATE_PREFIX}{var}:{float(distance)!r}"


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
    nonlinear: dict = field(default_factory=dict)  # shape parameters (e.g. omega_s, delta) and their SDs
    positive: bool = False  # physics requires a positive coefficient (e.g. T_S - T_C > 0)
    # nonlinear shape parameters identified from the data (CV profile search, hd_twin.identify):
    # ``make_basis(shape_dict)`` gives the basis at a shape; ``basis`` holds the current one
    shapes: list[Shape] = field(default_factory=list)
    make_basis: Callable[[dict], list[dict]] | None = field(repr=False, default=None)
    short_stroke: bool = False  # a smooth term in an angle whose periodicity is not identifiable
    test_cols: tuple[int, ...] | None = None  # columns whose identification decides (None: all)
    nuisance: tuple[str, ...] = ()  # shapes re-identified with the group whose identification does not decide
    replaces: tuple[str, ...] = ()  # baseline parameters whose columns the group replaces (e.g. "T_C")
    after: str | None = None  # a refinement: competes only once this family is selected (e.g. the next order)
    # a part of an effect that needs this family beside it in the final model (it may enter first, where it is the
    # larger part, but a model that keeps it without that family is no reading of the effect: the backward pass drops it)
    beside: str | None = None
    # (family, column): competes only while that family is selected with a positive coefficient on that column of its
    # group in the current model (a premise of the reading, e.g. a lost motion: the spring engages outside its width)
    needs_positive: tuple[str, int] | None = None
    # (family, shape): competes only while that family is selected with that shape above the low end of its search
    # range by two of its block-jackknife SDs (a premise on a width, e.g. a lost motion that is a gap, not a stand-in
    # for a curved law at the twist's noise level, the low end of its width range)
    needs_shape: tuple[str, str] | None = None
    # (family, its shape, this group's shape): this group's shape, identified given the current model, lies beyond
    # that selected family's shape (e.g. a knot of the torsion law beyond the lost motion's width); else it does not
    # compete at that step
    beyond: tuple[str, str, str] | None = None
    # competes at a forward step only where an earlier variant of its family (listed before it) lowers the CV error
    # at that step by one paired SE of the per-block drops (t >= 1): a costly shaped refinement of a plain reading
    # that the plain reading also partly sees
    screened: bool = False
    # a function of a position (an angle) times this factor ({"op": "const"} for none): the group must also lower
    # the CV error with a level of the factor per block as a nuisance (core.within_block_sse), i.e. by the angle's
    # motion within blocks, not by levels between blocks where the angle stands still (None: not tested)
    level_carrier: dict | list | None = None  # a list of specs: a level of each per block, free together
    # the level carrier at a shape, for a group whose factor has a shape parameter (``set_shape`` rebuilds it)
    make_carrier: Callable[[dict], dict | list] | None = field(repr=False, default=None)
    # parameters derived from the named ones and the shapes (e.g. db/dT of a law with an identified exponent)
    derived: Callable[[dict], dict] | None = field(repr=False, default=None)

    def set_shape(self, shape: dict, sd: dict | None = None) -> None:
        """Fix the shape parameters (and record their SDs): rebuilds ``basis`` (and the level carrier)."""
        self.basis = self.make_basis(shape)
        if self.make_carrier is not None:
            self.level_carrier = self.make_carrier(shape)
        self.nonlinear.update({k: float(v) for k, v in shape.items()})
        for k, v in (sd or {}).items():
            self.nonlinear[f"{k}_sd"] = float(v)

    def term(self, signal: str, coef) -> dict:
        """The fitted candidate as an ``hd_twin.terms`` term dict."""
        coef = np.asarray(coef, float)
        params = dict(self.nonlinear)
        params.update(self.to_parameters(coef))
        if self.derived is not None:
            params.update({k: float(v) for k, v in self.derived(params).items()})
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
    fric_spec: dict | None = None  # the baseline's friction direction when it is a pre-sliding state (else tanh)
    orders: dict[str, list[float]] = field(default_factory=dict)  # variable -> harmonic orders to try
    declared: set[str] = field(default_factory=set)  # the twin's declared effects (never re-proposed)
    excluded: set[str] = field(default_factory=set)  # names/variables that cannot be identified on these data
    n_pole_pairs_hint: int | None = None
    short_stroke: dict[str, tuple] = field(default_factory=dict)  # angle -> (centre, half range, lo, hi) of the fit data
    eps_range: tuple[float, float] | None = None  # rad/s, search range of the friction transition width
    presliding_range: tuple[float, float] | None = None  # rad, search range of a pre-sliding distance of theta_m
    windup_scale: float = 0.0  # rad, q90 of |w| (twist-side shape ranges)
    windup_noise: float = 0.0  # rad, white-noise sigma of w
    windup_dot_scale: float = 0.0  # rad/s, q90 of |w'|
    # s, the torque sample's skew after the angle's (Dataset.angle_skew): harmonics at theta + s omega (0: as logged)
    angle_skew: float = 0.0
    # a motor-angle ripple of tau_m is also offered as seen through the drive's band (``_band_limited``)
    band_limited: bool = True
    # the load-dependent friction also comes with its own identified transition (tanh width, pre-sliding distance)
    load_own_transition: bool = True


#: The rate of each angle (the re-timed angle theta + s omega of a position harmonic).
ANGLE_RATE = {"theta_m": "omega_m", "theta_f": "omega_f"}


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
            if c.name in ctx.excluded or (c.variable in ctx.excluded and not c.short_stroke):
                continue
            if any(r not in ctx.available for r in c.requires):
                continue
            out.append(c)
    return out


def _sgn(ctx, var="omega_m"):
    """The friction direction the baseline identified: tanh(omega_m / eps) or the pre-sliding state."""
    if var == "omega_m" and ctx.fric_spec is not None:
        return dict(ctx.fric_spec)
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
    # Stribeck: characteristic speed and shape exponent identified from the data (CV profile search), with
    # the Coulomb transition width re-identified jointly: a low-speed rise the baseline's width absorbed
    # (a steeper transition) is given back to the Stribeck term, not left for drag or bias terms
    lo = max(ctx.omega_low * 0.05, 1e-3)
    hi = max(ctx.omega_scale * 0.6, lo * 2)
    e0 = ctx.sgn_eps

    def stribeck_basis(sh):
        eps = float(sh["eps"])
        return [{"op": "sgn", "var": "omega_m", "eps": eps},
                {"op": "stribeck", "var": "omega_m", "v_s": float(sh["omega_s"]), "delta": float(sh["delta"]),
                 "eps": eps}]

    sh0 = {"omega_s": float(np.sqrt(lo * hi)), "delta": 1.0, "eps": e0}
    if ctx.fric_spec is not None:
        # the baseline's friction follows a pre-sliding state s: the Stribeck excess rides on the same state
        # (LuGre's g(omega) = T_C + (T_S - T_C) exp(-(|omega|/omega_s)^delta) scales the bristle state)
        def stribeck_state(sh):
            z = dict(ctx.fric_spec)
            return [dict(z), {"op": "prod", "factors": [{"op": "exp_decay", "var": "omega_m", "v_s": float(sh["omega_s"]),
                                                         "delta": float(sh["delta"])}, dict(z)]}]
        sh1 = {"omega_s": sh0["omega_s"], "delta": 1.0}
        out.append(Candidate(
            "stribeck_friction", "stribeck", "omega_m", None, stribeck_state(sh1),
            "[T_C + (T_S - T_C) exp(-(|omega_m|/omega_s)^delta)] s, s the pre-sliding state of theta_m",
            lambda c: {"T_C": float(c[0]), "T_S_minus_T_C": float(c[1])},
            requires=("omega_m",), nonlinear=dict(sh1), positive=True, test_cols=(1,),
            shapes=[Shape("omega_s", lo, hi, log=True, n_grid=8), Shape("delta", 0.3, 5.0, log=True, n_grid=5)],
            nuisance=("delta",), replaces=("T_C",), make_basis=stribeck_state,
        ))
    if ctx.fric_spec is None:
        out.append(Candidate(
            "stribeck_friction", "stribeck", "omega_m", None, stribeck_basis(sh0),
            "T_C tanh(omega_m/eps) + (T_S - T_C) exp(-(|omega_m|/omega_s)^delta) tanh(omega_m/eps)",
            lambda c: {"T_C": float(c[0]), "T_S_minus_T_C": float(c[1])},
            requires=("omega_m",), nonlinear=dict(sh0), positive=True, test_cols=(1,),
            shapes=[Shape("omega_s", lo, hi, log=True, n_grid=8), Shape("delta", 0.3, 5.0, log=True, n_grid=5),
                    Shape("eps", *ctx.eps_range, log=True, n_grid=8)] if ctx.eps_range else
                   [Shape("omega_s", lo, hi, log=True, n_grid=8), Shape("delta", 0.3, 5.0, log=True, n_grid=5)],
            # the curve decides: omega_s must be identified; the exponent trades off against omega_s on finite
            # data (reported with its SD, or as a bound), the width is the baseline's, re-identified
            nuisance=("eps", "delta"), replaces=("T_C",),
            make_basis=stribeck_basis,
        ))
    # Temperature-dependent friction: viscous and Coulomb coefficients drifting with T. The viscous part's preferred
    # reading is Reynolds' viscosity law, b(T) = b exp(-beta (T - T_ref)) (a lubricant's viscosity falls exponentially
    # with temperature, Reynolds 1886; over tens of K the linear law is far from it: -30 K at beta = 0.03/K is x2.46,
    # not x1.9, so a law fitted on warm missions misses on a cold one), its exponent identified by the CV profile over
    # the range of lubricants and greases (0.002-0.2 /K; at the low end the law is linear over any realistic span);
    # the linear law stays as the alternative (a viscosity rising with T, or a Coulomb-only drift): the family keeps
    # whichever explains the data better by more than the tie margin, Reynolds' on a tie. beta is reported with its
    # SD, never a reason to reject the family (a short temperature span only bounds it); the coefficients decide.
    tref = {"op": "offset", "var": "temperature", "ref": ctx.t_ref}

    def reynolds_basis(sh):
        e = {"op": "expm1", "var": "temperature", "k": -float(sh["beta"]), "ref": ctx.t_ref}
        return [{"op": "prod", "factors": [{"op": "var", "var": "omega_m"}, e]},
                {"op": "prod", "factors": [_sgn(ctx), tref]}]

    out.append(Candidate(
        "temperature_dependent_friction", "temperature", "temperature", None, reynolds_basis({"beta": 0.02}),
        "b_T omega_m (exp(-beta (T - T_ref)) - 1) + dT_C/dT sgn(omega_m) (T - T_ref) (Reynolds' viscosity law: "
        "b(T) = b + b_T (exp(-beta (T - T_ref)) - 1), db/dT = -beta b_T at T_ref)",
        lambda c: {"b_T": float(c[0]), "dT_C_dT": float(c[1])},
        derived=lambda p: {"db_dT": -p["beta"] * p["b_T"]},
        requires=("omega_m", "temperature"), nonlinear={"T_ref": ctx.t_ref, "beta": 0.02},
        shapes=[Shape("beta", 0.002, 0.2, log=True, n_grid=8)], nuisance=("beta",), make_basis=reynolds_basis,
    ))
    out.append(Candidate(
        "temperature_dependent_friction", "temperature", "temperature", None,
        [{"op": "prod", "factors": [{"op": "var", "var": "omega_m"}, tref]},
         {"op": "prod", "factors": [_sgn(ctx), tref]}],
        "(db/dT omega_m + dT_C/dT sgn(omega_m)) (T - T_ref)",
        lambda c: {"db_dT": float(c[0]), "dT_C_dT": float(c[1])},
        requires=("omega_m", "temperature"), nonlinear={"T_ref": ctx.t_ref},
    ))
    # The torque constant's drift with temperature (motor_thermal_drift): the magnets' flux linkage falls with
    # temperature (the torque estimate drifts by about -0.1 %/K; PHYSICS.md's
    # effect table: regress on T i_q), while the drive logs tau_m = k_t,nom i_q with its
    # nominal constant. The shaft torque is k_t,nom (1 - a (T - T_ref)) i_q, so against a torque balance fitted at
    # T_ref the logged torque carries + k_t,nom a (T - T_ref) i_q: the current itself scaled by the temperature
    # offset, whatever the current is spent on (inertia, load, friction). That is no friction term: a friction
    # drift (the family above) scales sgn(omega_m) and omega_m, not the load path's share. The measured current
    # (i_q = tau_m / k_t) is the regressor; the temperature is the logged one (the twin's, gearbox: the magnets'
    # own temperature is logged by no drive); T_ref the fit data's median, so the current's noise, which the
    # torque shares, averages out of the coefficient. k_t a > 0 for a constant that falls as the magnets warm.
    out.append(Candidate(
        "motor_thermal_drift", "torque_constant", "temperature", None,
        [{"op": "prod", "factors": [{"op": "var", "var": "i_q"}, dict(tref)]}],
        "k_t alpha_T (T - T_ref) i_q (the torque constant k_t (1 - alpha_T (T - T_ref)) against the logged "
        "tau_m = k_t,nom i_q)",
        lambda c: {"k_t_alpha_T": float(c[0])},
        requires=("i_q", "temperature"), nonlinear={"T_ref": ctx.t_ref},
    ))
    # Load-dependent (Coulomb share proportional to the transmitted torque). Its passage through zero speed is the
    # load path's own: a tooth-flank contact sliding under load, felt at the motor through the wave generator's
    # bearing and the flexspline's compliance, is no reason to share the bearings' and seals' transition the baseline
    # identified. So besides the baseline's direction the term comes with its own, identified as the baseline's is:
    # tanh(omega_m / eps_L) over the baseline width's search range, and a pre-sliding state of theta_m at its own
    # distance d_L over the baseline's range of distances (a contact that sticks and leaves its direction over a
    # travel). The shape is a nuisance (the coefficient decides); the family keeps the variant that generalises best.
    qabs = {"op": "abs", "var": "Q_red"}
    out.append(Candidate(
        "load_dependent_friction", "load", "Q_red", None,
        [{"op": "prod", "factors": [dict(qabs), _sgn(ctx)]}],
        "c_L |Q_red| sgn(omega_m)",
        lambda c: {"c_L": float(c[0])},
        requires=("omega_m", "Q_red"),
    ))
    if ctx.load_own_transition and ctx.eps_range is not None:
        def load_tanh(sh):
            return [{"op": "prod", "factors": [dict(qabs), {"op": "sgn", "var": "omega_m", "eps": float(sh["eps_L"])}]}]

        e_l = float(np.clip(ctx.sgn_eps, *ctx.eps_range))
        out.append(Candidate(
            "load_dependent_friction", "load", "Q_red", None, load_tanh({"eps_L": e_l}),
            "c_L |Q_red| tanh(omega_m / eps_L) (the load path's own transition width)",
            lambda c: {"c_L": float(c[0])},
            requires=("omega_m", "Q_red"), nonlinear={"eps_L": e_l},
            shapes=[Shape("eps_L", *ctx.eps_range, log=True, n_grid=8)], nuisance=("eps_L",), make_basis=load_tanh,
        ))
    if (ctx.load_own_transition and ctx.presliding_range is not None
            and ctx.presliding_range[1] > ctx.presliding_range[0]):
        d_lo, d_hi = ctx.presliding_range

        def load_state(sh):
            s = {"op": "var", "var": state_var("theta_m", float(sh["d_L"]))}
            return [{"op": "prod", "factors": [dict(qabs), s]}]

        d0 = float(np.sqrt(d_lo * d_hi))
        out.append(Candidate(
            "load_dependent_friction", "load", "Q_red", None, load_state({"d_L": d0}),
            "c_L |Q_red| s, s the pre-sliding state of theta_m at the load path's own distance d_L",
            lambda c: {"c_L": float(c[0])},
            requires=("omega_m", "Q_red", "theta_m"), nonlinear={"d_L": d0},
            shapes=[Shape("d_L", d_lo, d_hi, log=True, n_grid=8)], nuisance=("d_L",), make_basis=load_state,
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
        rate = ANGLE_RATE.get(var)
        skew = ctx.angle_skew if rate in ctx.available else 0.0
        at = (f" [{var} re-timed by the acquisition skew: {var} + s {rate}, s = {skew * 1e3:.3g} ms]" if skew else "")

        def pair(k, times=None, var=var, skew=skew, rate=rate):
            return sin_cos_pair(var, float(k), times, skew_s=skew, rate=rate)
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
                    pair(k, times), form + at, _harm_params(pname, k),
                    requires=tuple({var} | ({measured_signal(times["var"])} if times and "var" in times else set())
                                   | ({rate} if skew else set())),
                    # i_q is the target itself (tau_m / k_t): a level of it per block would rescale the target, no
                    # nuisance that can be fitted, so the i_q variant is not tested (its ripple scales with the current)
                    level_carrier=None if variant == "iq" else dict(times) if times else {"op": "const"},
                ))
                if (ctx.band_limited and variant in ("plain", "iq") and ctx.target == "tau_m" and var == "theta_m"
                        and "omega_m" in ctx.available):
                    out.append(_band_limited(ctx, k, fam, variant, times, form + at, pname, pair, rate, skew))
            if ctx.target == "Q_red" and "windup" in ctx.available and var == "theta_m" and float(k).is_integer():
                # load-dependent amplitude of the same ripple (e.g. the KE's A_k(1 + a_T |T|/T_rated)): an
                # additional group in its own family, so that it can join the plain ripple, never replace it
                out.append(Candidate(
                    _periodic_name(ctx.target, var, k, "plain"), f"{fam}:load", var, float(k),
                    pair(k, {"op": "abs", "var": "windup"}),
                    f"K a_{ks} |w| sin({ks} {var} + psi_{ks}), w = theta_m/N - theta_f (load-dependent amplitude)" + at,
                    _harm_params("K_a", k), requires=(var, "windup"),
                    level_carrier={"op": "abs", "var": "windup"},
                ))
                # the same ripple through a hardening torsion law's local stiffness: a position error e(theta)
                # inside the spring gives Q = f(w - e) ~ f(w) - f'(w) e, and with f = K w + k3 w^3 the
                # f'(w) e part is K e (the plain ripple) plus 3 k3 w^2 e (this group, in its own family so
                # that it can join the plain ripple); the data decide (CV + Wald) whether the law is curved.
                # The K e part comes with every w^2 e part, since K > 0 is the law's slope at zero twist, so a final
                # model with a w^2 ripple and no plain ripple of its order is no reading of this effect (``beside``;
                # on clean hysteretic-robot data, seed 12700, one entered alone at the Wald rule's knife edge and
                # was named as a kinematic error the plant does not have). It may enter first: on a strongly curved
                # law the w^2 part is the larger one, and the plain ripple joins it after
                out.append(Candidate(
                    _periodic_name(ctx.target, var, k, "plain"), f"{fam}:stiff", var, float(k),
                    pair(k, {"op": "pow", "var": "windup", "p": 2.0}),
                    f"K b_{ks} w^2 sin({ks} {var} + psi_{ks}), w = theta_m/N - theta_f (the ripple through the "
                    "torsion law's local stiffness)" + at,
                    _harm_params("K_b", k), requires=(var, "windup"),
                    level_carrier={"op": "pow", "var": "windup", "p": 2.0}, beside=fam,
                ))
                if ctx.windup_scale > 0:
                    out.append(_contact_ripple(ctx, var, k, fam, pair, at))
    return out


def band_corner_range(k: float, omega_low: float, omega_scale: float) -> tuple[float, float]:
    """The range of a band-limited order-k ripple's corner omega_b [rad/s of the ripple's frequency]: from k times the
    Stribeck speed's low end (0.05 of the low-speed scale ``omega_low``) to twice the high-speed scale
    ``omega_scale`` times k. At k = 1: the half-share speeds omega_b / k (``spectrum.band_line_scan``'s)."""
    lo = k * max(0.05 * omega_low, 1e-3)  # the low end of the Stribeck speed's range, as a ripple frequency
    return lo, max(2.0 * k * omega_scale, 4.0 * lo)


def _band_limited(ctx: LibraryContext, k: float, fam: str, variant: str, times, form: str, pname: str, pair,
                  rate: str | None, skew: float) -> Candidate:
    """The same motor-angle ripple as it shows in the logged torque of a drive whose loops have a finite band.

    A torque periodic in theta_m (cogging, the drive's current ripple, any position disturbance of the motor) is a
    disturbance at the frequency k |omega_m|. The drive's speed loop answers it with current, which the log shows as
    tau_m = k_t i_q, only within its band; beyond it the rotor's inertia takes the ripple as a speed ripple, which
    the encoder's differentiated and smoothed acceleration does not carry either. So the ripple a log shows fades
    with k |omega_m|: a plain harmonic fitted over all speeds is pulled towards zero by the fast rows (where it is
    not seen) and predicts a ripple there that is not (a held-out mission at other speeds then scores it worse).

    This variant scales the harmonic by the share 1 / (1 + (k omega_m / omega_b)^2) of a band-limited loop. Its
    corner omega_b [rad/s of the ripple's frequency] is identified by the CV profile over the ripple frequencies of
    the data: from k times the Stribeck speed's low end (0.05 of the low-speed scale; a ripple seen only in the
    slowest rows, around the reversals, must be in range) to twice the high-speed scale times k. It is the plain
    harmonic's variant in the same family, so the data decide between them; an unbounded band (omega_b at the top
    of its range) is the plain reading and leaves omega_b unidentified. The magnitude only: a phase lag that grows
    with speed was tried and left about 9 % more CV SSE on hd_sim's deadzone-lugre cogging (perhaps the loop's lag
    and the acceleration estimate's filter partly cancel; not measured); the harmonic's own phase is free as in the
    plain reading.

    Its shape costs a CV profile per forward step, so it competes only where the plain harmonic (or the
    current-proportional one), listed just before it, lowers the CV error at that step by one paired SE
    (``screened``): the slow rows show a band-limited ripple whole, so the plain reading gains there too."""
    ks = _kstr(k)
    lo, hi = band_corner_range(k, ctx.omega_low, ctx.omega_scale)

    def factor(sh):
        lp = {"op": "lowpass", "var": "omega_m", "k": float(k), "corner": float(sh["omega_b"])}
        return lp if times is None else {"op": "prod", "factors": [dict(times), lp]}

    def carriers(sh):
        # where theta_m stands (nearly) still the ripple is a level times its share: a level of the share per block
        # is freed, and a plain level besides. A parked, dithering drive's share follows the dither speed, so a
        # per-mission offset looks like a low-corner ripple in every parked block (test_discovery_between_levels:
        # parked missions at different angles, where an order-3 ripple with omega_b = 11 rad/s took the offsets)
        return [{"op": "const"}, factor(sh)]

    def basis(sh):
        return pair(k, factor(sh))

    sh0 = {"omega_b": float(np.sqrt(lo * hi))}
    return Candidate(
        _periodic_name(ctx.target, "theta_m", k, variant), fam, "theta_m", float(k), basis(sh0),
        form + f" / (1 + ({ks} omega_m / omega_b)^2) (seen through the drive's band: beyond the corner omega_b of "
        "the ripple's frequency the rotor's inertia takes it, and the logged current does not show it)",
        _harm_params(pname, k), derived=lambda p: {"f_b_hz": p["omega_b"] / (2.0 * math.pi)},
        requires=tuple({"theta_m", "omega_m"} | ({"i_q"} if variant == "iq" else set()) | ({rate} if skew else set())),
        nonlinear=dict(sh0), shapes=[Shape("omega_b", lo, hi, log=True, n_grid=10)], make_basis=basis,
        level_carrier=None if variant == "iq" else carriers(sh0),
        make_carrier=None if variant == "iq" else carriers, screened=True,
    )


def _twist_range(ctx: LibraryContext) -> tuple[float, float]:
    """The range a twist-side width is searched over [rad]: from the twist's noise (or 1e-4 of its scale) to 0.6 of
    its scale (q90 of |w|)."""
    w_lo = max(ctx.windup_noise, 1e-4 * ctx.windup_scale, 1e-12)
    return w_lo, max(0.6 * ctx.windup_scale, 4 * w_lo)


def _contact_ripple(ctx: LibraryContext, var: str, k: float, fam: str, pair, at: str) -> Candidate:
    """The ripple's refinement for a transmission with lost motion: no ripple inside the dead zone.

    A position error e(theta) acts inside the spring, Q = f(w - e) ~ f(w) - f'(w) e: through the torsion law's local
    stiffness. A law with lost motion of half-width j has f' = 0 for |w| < j (no tooth contact, PHYSICS.md 2.2), so
    the kinematic error's torque ripple vanishes there: K e(theta) 1[|w| > j] = K e(theta) - K e(theta) 1[|w| < j].
    This group is the second part, ``B_k sin(k theta + psi) 1[|w| < j]``: it joins the plain ripple (a refinement,
    competing only once the plain ripple is selected, and only beside a selected lost motion whose spring engages
    outside its width, K_j > 0: its premise; B_k = -A_k for a ripple that vanishes inside the dead zone) and
    its width j is identified by the CV profile over the twist's range, as the dead zone's own width is
    (``twist_shape_candidates``), never assumed equal to it; the data decide (CV, within-block, Wald, shape)."""
    w_lo, w_hi = _twist_range(ctx)
    j0 = float(np.sqrt(w_lo * w_hi))
    ks = _kstr(k)

    def inside(sh):
        return {"op": "within", "var": "windup", "width": float(sh["j"])}

    return Candidate(
        _periodic_name(ctx.target, var, k, "plain"), f"{fam}:contact", var, float(k),
        pair(k, inside({"j": j0})),
        f"K c_{ks} sin({ks} {var} + psi_{ks}) 1[|w| < j], w = theta_m/N - theta_f (the ripple inside a lost motion "
        "of half-width j, where no teeth are in contact: c = -A for a ripple that vanishes there)" + at,
        _harm_params("K_c", k), requires=(var, "windup"), after=fam, needs_positive=("backlash", 0),
        nonlinear={"j": j0}, shapes=[Shape("j", w_lo, w_hi, log=True, n_grid=12)],
        make_basis=lambda sh: pair(k, inside(sh)),
        level_carrier=inside({"j": j0}), make_carrier=inside,
    )


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
        # the law's quadratic odd term, a refinement of the cubic: a local stiffness K + 2 k2 |w| that grows linearly
        # with the twist (the smooth reading of the catalogue's three-slope law, PHYSICS.md 2.1, whose stiffness
        # rises with load from zero twist; the cubic's K + 3 k3 w^2 rises quadratically). A measured law is an odd
        # function of unknown form: w, w |w|, w^3, w^5 are its odd series in |w|, and selection decides (CV, Wald)
        Candidate("nonlinear_stiffness", "stiffness:2", "windup", None,
                  [{"op": "prod", "factors": [{"op": "var", "var": "windup"}, {"op": "abs", "var": "windup"}]}],
                  "k2 w |w| (quadratic odd term of the torsion law after k3 w^3), w = theta_m/N - theta_f",
                  lambda c: {"k2": float(c[0])}, requires=("windup",), after="stiffness"),
        Candidate("unknown", "bias", None, None, [{"op": "const"}], "c_0", lambda c: {"c_0": float(c[0])}),
    ]


@register_candidate_builder
def torsion_order_candidates(ctx: LibraryContext) -> list[Candidate]:
    """The torsion law's next odd order, k5 w^5, as a refinement of a selected cubic k3 w^3.

    A measured twist-to-torque law is a smooth odd function whose polynomial degree is not known in
    advance (a hardening mesh spring in series with linear compliances, PHYSICS.md 1.2, is not a pure
    cubic in the measured twist); the degree is chosen like any group: the w^5 term competes only after the
    cubic is selected and enters only if it lowers the fit blocks' CV error by ``min_gain`` and its
    coefficient is identified (jackknife Wald). Named ``nonlinear_stiffness``: it is the same law.
    """
    if ctx.target != "Q_red" or "windup" not in ctx.available:
        return []
    return [Candidate("nonlinear_stiffness", "stiffness:5", "windup", None,
                      [{"op": "pow", "var": "windup", "p": 5.0}],
                      "k5 w^5 (next odd order of the torsion law after k3 w^3), w = theta_m/N - theta_f",
                      lambda c: {"k5": float(c[0])}, requires=("windup",), after="stiffness")]


@register_candidate_builder
def torsion_knot_candidates(ctx: LibraryContext) -> list[Candidate]:
    """Knots of the catalogue's piecewise-linear torsion law: a slope change dK dz(w; u) at an identified twist u.

    The catalogue describes the twist-to-torque curve by slopes K1, K2, K3 between break points (PHYSICS.md 2.1):
    K w + dK_1 dz(w; u_1) + dK_2 dz(w; u_2), dz(w; u) = sgn(w) max(|w| - u, 0). Beyond a lost motion (a selected
    dead zone) the spring's own law is that curve of the engaged twist, and a polynomial in the *measured* twist
    (k3 w^3, k5 w^5) continues it only roughly: the dead zone shifts the curve by j, so its curvature sits at
    |w| ~ j + u, where powers of w bend from zero. A knot is a refinement: it competes once the lost motion is
    selected as a gap (its width two SDs above the low end of its range, the twist's noise: a dead zone there stands
    in for a curved law, whose odd series then reads the curve), lies beyond the gap (u > j: a slope change inside
    the gap is a soft edge of the dead zone, which a position error moving the edge also makes, not a knot of the
    spring's law) and needs the lost motion beside it in the final model; u is identified by the CV profile over the twist's range
    (as the dead zone's own width is) and reported with its uncertainty, dK by the jackknife Wald rule. A second
    knot competes once the first is selected (the catalogue's third slope). Named ``nonlinear_stiffness``: the
    law's shape. Without a lost motion the law's odd series (k3 w^3, k2 w |w|, k5 w^5) reads the curve: a knot
    after the cubic took the quintic's place on a cubic law (smooth-cubic, seed 100: CV gains 0.2495 against
    0.2487) and extrapolated worse (held-out 3.70 against 3.34), a linear continuation where the law keeps
    hardening."""
    if ctx.target != "Q_red" or "windup" not in ctx.available or ctx.windup_scale <= 0:
        return []
    w_lo, w_hi = _twist_range(ctx)
    u0 = float(np.sqrt(w_lo * w_hi))

    def knot_basis(sh):
        return [{"op": "deadzone", "var": "windup", "width": float(sh["u"])}]

    out = []
    # (family, the family it refines and needs beside it in the final model, knot index): a knot read beside a lost
    # motion that the backward pass then drops would be a one-column dead zone named as a stiffness
    for fam, after, idx in (("stiffness:knot", "backlash", 1), ("stiffness:knot2", "stiffness:knot", 2)):
        out.append(Candidate(
            "nonlinear_stiffness", fam, "windup", None, knot_basis({"u": u0}),
            f"dK_{idx} dz(w; u_{idx}) (a knot of the piecewise-linear torsion law: the slope changes by dK_{idx} "
            f"beyond |w| = u_{idx}), dz = sgn(w) max(|w| - u, 0), w = theta_m/N - theta_f",
            lambda c, i=idx: {f"dK_{i}": float(c[0])}, requires=("windup",), after=after, beside=after,
            needs_shape=("backlash", "j"), beyond=("backlash", "j", "u"),
            nonlinear={"u": u0}, shapes=[Shape("u", w_lo, w_hi, log=True, n_grid=12)], make_basis=knot_basis,
        ))
    return out


@register_candidate_builder
def short_stroke_candidates(ctx: LibraryContext) -> list[Candidate]:
    """A smooth, non-periodic term in an angle whose stroke is too short to identify a periodicity.

    Powers 1..3 of (angle - centre) over the angle's range (a torque that depends on position, e.g. a
    position-periodic torque seen over part of one period): reported ``unknown`` with ``variable`` set,
    so such a structure is not taken by a constant bias.
    """
    out: list[Candidate] = []
    for var, ss in ctx.short_stroke.items():
        centre, half = ss[0], ss[1]
        lo, hi = (ss[2], ss[3]) if len(ss) > 3 else (centre - half, centre + half)
        if var not in ctx.available or half <= 0:
            continue
        # with the constant: the mean of such a torque over the stroke is part of it, not a separate bias. Each
        # power is (angle - centre)^k over the fit data's range [lo, hi] and continued linearly beyond it
        # (hd_twin.terms.pow_within: the function is identified on that range only; a cubic's u^3 beyond it is no
        # evidence of anything); on the fit rows the columns are the plain powers
        powers = [{"op": "const"}] + [{"op": "pow", "var": var, "p": float(k), "ref": centre, "lo": lo, "hi": hi}
                                      for k in (1, 2, 3)]
        rng = f" on [{lo:.4g}, {hi:.4g}], continued linearly beyond"
        variants = [("plain", None, f"p0 + p1 u + p2 u^2 + p3 u^3, u = {var} - {centre:.4g}{rng}")]
        if ctx.target == "tau_m" and "omega_m" in ctx.available:
            variants.append(("sgn", _sgn(ctx), f"(p0 + p1 u + p2 u^2 + p3 u^3) sgn(omega_m), u = {var} - {centre:.4g}{rng}"))
        for variant, times, form in variants:
            basis = powers if times is None else [{"op": "prod", "factors": [b, dict(times)]} for b in powers]
            out.append(Candidate(
                "unknown", f"{var}:smooth", var, None, basis, form,
                lambda c, h=half, lo=lo, hi=hi: {"p0": float(c[0]), "p1": float(c[1]), "p2": float(c[2]),
                                                 "p3": float(c[3]), "range_half_width": h, "range_lo": lo,
                                                 "range_hi": hi},
                requires=(var,) + (("omega_m",) if times else ()), short_stroke=True,
                level_carrier=dict(times) if times else {"op": "const"},
            ))
    return out


@register_candidate_builder
def twist_shape_candidates(ctx: LibraryContext) -> list[Candidate]:
    """Twist-side effects with an identified shape: lost motion (dead zone of width j) and hysteresis."""
    if ctx.target != "Q_red" or "windup" not in ctx.available or ctx.windup_scale <= 0:
        return []
    out = []
    w_lo, w_hi = _twist_range(ctx)

    def dz_basis_diff(sh):
        # with the baseline's K w (and a cubic k3 w^3 if selected) these span K dz(w) + k3 dz(w)^3: the
        # lost motion applied to the linear and the cubic law
        d = {"op": "deadzone", "var": "windup", "width": float(sh["j"])}
        return [{"op": "prod", "factors": [d]}, {"op": "prod", "factors": [d, d, d]}]

    c = Candidate(
        "backlash", "backlash", "windup", None, dz_basis_diff({"j": np.sqrt(w_lo * w_hi)}),
        "K_j dz(w; j) + k3_j dz(w; j)^3, dz = sgn(w) max(|w| - j, 0), w = theta_m/N - theta_f",
        lambda c: {"K_j": float(c[0]), "k3_j": float(c[1])}, requires=("windup",),
        nonlinear={"j": float(np.sqrt(w_lo * w_hi))},
        shapes=[Shape("j", w_lo, w_hi, log=True, n_grid=12)], make_basis=dz_basis_diff,
    )
    out.append(c)

    # hysteresis as the rate-independent state of the twist (Dahl; Bouc-Wen with n = 1, gamma = 0: PHYSICS.md
    # 2.2): the transmitted torque gains T_h s, s leaving its old level over a twist travel d_h after each
    # reversal of the twist; the loop's width at zero torque is 2 T_h / K. d_h identified by the CV profile
    def dahl_basis(sh):
        return [{"op": "var", "var": state_var("windup", sh["d_h"])}]

    out.append(Candidate(
        "hysteresis", "hysteresis", "windup", None, dahl_basis({"d_h": np.sqrt(w_lo * w_hi)}),
        "T_h s(w; d_h), ds/dw = (sgn(dw) - s) / d_h (Dahl / Bouc-Wen state of the twist w = theta_m/N - theta_f)",
        lambda c: {"T_h": float(c[0])}, requires=("windup",),
        # a hysteresis loop dissipates: T_h > 0
        positive=True, nonlinear={"d_h": float(np.sqrt(w_lo * w_hi))},
        # up to the peak-to-peak twist: a longer distance never approaches saturation (s linear in the travel)
        shapes=[Shape("d_h", w_lo, max(2.0 * ctx.windup_scale, 4 * w_lo), log=True, n_grid=12)],
        # the loop decides (T_h, jackknife Wald and CV); a loop that never saturates within the twist range
        # bounds d_h only from below: reported with that note, not a reason to reject the loop
        nuisance=("d_h",), make_basis=dahl_basis,
    ))
    if "windup_q" in ctx.available:
        # the same state driven by the twist as its encoders resolve it (data.signals_of_mission: count
        # toggles of the quantised twist are not load reversals); an alternative of the same family, the
        # CV profile and selection decide between them
        def dahl_q_basis(sh):
            return [{"op": "var", "var": state_var("windup_q", sh["d_h"])}]

        out.append(Candidate(
            "hysteresis", "hysteresis", "windup", None, dahl_q_basis({"d_h": np.sqrt(w_lo * w_hi)}),
            "T_h s(w_q; d_h), ds/dw_q = (sgn(dw_q) - s) / d_h, w_q: the twist w = theta_m/N - theta_f through a "
            "play of one encoder step (reversals within the twist's resolution are not counted)",
            lambda c: {"T_h": float(c[0])}, requires=("windup_q",),
            positive=True, nonlinear={"d_h": float(np.sqrt(w_lo * w_hi))},
            shapes=[Shape("d_h", w_lo, max(2.0 * ctx.windup_scale, 4 * w_lo), log=True, n_grid=12)],
            nuisance=("d_h",), make_basis=dahl_q_basis,
        ))
    if "windup_dot" in ctx.available and ctx.windup_dot_scale > 0:
        v_lo = max(1e-4 * ctx.windup_dot_scale, 1e-12)
        v_hi = 0.5 * ctx.windup_dot_scale

        def hyst_basis(sh):
            return [{"op": "sgn", "var": "windup_dot", "eps": float(sh["eps_h"])}]

        out.append(Candidate(
            "hysteresis", "hysteresis", "windup", None, hyst_basis({"eps_h": np.sqrt(v_lo * v_hi)}),
            "T_h tanh(w'/eps_h), w = theta_m/N - theta_f",
            lambda c: {"T_h": float(c[0])}, requires=("windup_dot",),
            # a hysteresis loop dissipates: the loop integral of Q_red dw = T_h * total |dw| > 0
            positive=True, nonlinear={"eps_h": float(np.sqrt(v_lo * v_hi))},
            shapes=[Shape("eps_h", v_lo, v_hi, log=True, n_grid=10)], make_basis=hyst_basis,
        ))
    return out


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
