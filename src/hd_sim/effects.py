"""The one registry of every switchable physical (and sensor) effect of the plant.

Each effect has a canonical name (PHYSICS.md section 7 where one exists), a
realistic default (``default_on``), a flag saying whether a *basic twin*
declares it (``baseline``), and its parameters with units. The plant reads
effects only through :class:`EffectSet`, so data with any effect on or off is
made the same way from the CLI (``--effect NAME=on|off --param NAME.KEY=VALUE``)
and from tests (``EffectSet.baseline().with_on("stribeck_friction")``).

The **baseline** set is what a basic twin declares: rigid-body inertias, the
linear three-body compliance chain (bearing, flexspline, mesh; linear mesh
stiffness = the catalogue's K3 slope), Coulomb and viscous friction on both
sides, the aerodynamic hinge moment with gusts, the thermal nodes (losses heat
the winding and grease, nothing depends on temperature), wear bookkeeping, and
realistic sensors (quantisation + noise). Every other effect is individually
switchable on top of it and each changes only its own term.

Effect amplitudes whose size differs from unit to unit (e.g. the KE phase)
are drawn per actuator by :func:`hd_sim.params.sample_population`; the values
here are the nominal ones. A parameter set with ``--param`` overrides both.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping


@dataclass(frozen=True)
class Effect:
    name: str
    category: str  # friction | transmission | motor | load | thermal | degradation | sensor
    doc: str
    default_on: bool
    baseline: bool
    params: Mapping[str, tuple[float, str, str]] = field(default_factory=dict)  # key -> (default, unit, doc)
    slot: str = ""  # law slot (LAW_SLOTS) this effect is one choice of; "" = an independent effect


def _E(name, category, doc, default_on, baseline, slot="", **params):
    return Effect(name, category, doc, default_on, baseline, params, slot)


#: name -> Effect. Order = the order ``hdphm sim effects`` prints.
REGISTRY: dict[str, Effect] = {e.name: e for e in (
    # ---- friction ------------------------------------------------------------------------
    _E("coulomb_friction", "friction",
       "Coulomb friction T_C sgn(omega_m) at the input (WG plug, motor bearings, mesh no-load share) "
       "and T_C_out sgn(omega_f) at the output cross-roller bearing; sgn regularised as tanh(omega/eps_v).",
       True, True,
       T_C=(1.5, "N*m", "input-side Coulomb torque at T_ref (size-65 scale of 0.05-0.15 N*m at size 25)"),
       T_C_out=(5.0, "N*m", "output-bearing Coulomb torque"),
       eps_v=(0.02, "rad/s", "motor-speed regularisation of sgn()")),
    _E("viscous_friction", "friction", "Viscous drag b omega_m (input) and b_out omega_f (output) at T_ref.",
       True, True,
       b=(2.0e-3, "N*m*s/rad", "input-side viscous coefficient at T_ref"),
       b_out=(20.0, "N*m*s/rad", "output-side viscous coefficient at T_ref")),
    _E("smooth_friction", "friction",
       "Law choice (slot friction_transition = tanh): Coulomb and Stribeck torques pass through zero speed as "
       "tanh(omega_m/width) at the input and tanh(omega_f N/width) at the output, a width of the order of "
       "real drives' measured transition (instead of the near-hard sign of eps_v = 0.02 rad/s).", False, False,
       slot="friction_transition",
       width=(1.0, "rad/s", "motor-speed width of the transition (0.2-5 rad/s); replaces coulomb_friction.eps_v")),
    _E("lugre_friction", "friction",
       "Law choice (slot friction_transition = lugre): LuGre dynamic friction (Canudas de Wit et al. 1995) on "
       "the input Coulomb + Stribeck torque: dz/dt = omega_m - sigma0 |omega_m| z / g(omega_m), "
       "T = sigma0 z + sigma1 dz/dt (+ viscous), g = T_C (+ Stribeck); pre-sliding spring sigma0 below "
       "breakaway. The mesh flank friction and the output bearing keep tanh(omega/eps_v).", False, False,
       slot="friction_transition",
       sigma0=(2000.0, "N*m/rad", "bristle stiffness at the motor (pre-sliding travel T_C/sigma0 ~ 1e-3 rad)"),
       sigma1=(0.02, "N*m*s/rad", "bristle damping"),
       eps_v=(1.0, "rad/s", "tanh width of the mesh flank friction and the output bearing under this law")),
    _E("stribeck_friction", "friction",
       "(T_S - T_C) exp(-(|omega_m|/omega_s)^delta) sgn(omega_m) at the input.", True, False,
       ratio=(1.35, "-", "breakaway / Coulomb ratio T_S/T_C"),
       omega_s=(5.0, "rad/s", "Stribeck velocity at the motor"),
       delta=(1.5, "-", "Stribeck exponent")),
    _E("temperature_dependent_friction", "friction",
       "Grease viscosity nu(T_h) = nu_ref exp(-beta (T_h - T_ref)) scales b by (nu/nu_ref)^n_b and the "
       "Coulomb torques by (nu/nu_ref)^n_c (both sides).", True, False,
       beta=(0.03, "1/K", "viscosity-temperature coefficient (halves every ~23 K)"),
       T_ref=(25.0, "degC", "reference temperature of b and T_C"),
       n_b=(0.8, "-", "viscous exponent"),
       n_c=(0.3, "-", "Coulomb exponent (+37 % at -10 degC)")),
    _E("load_dependent_friction", "friction",
       "Tooth-flank sliding friction at the mesh: F_mx = mu_g F_my + mu_c |F_my| sgn(omega_m), "
       "mu_c = mu_flank * mu_g (the flank coefficient projected on the radial stroke); loads the WG "
       "through F_b, so input-side loss grows with |Q_red| (efficiency rises with load).", True, False,
       mu_flank=(0.08, "-", "tooth-flank friction coefficient in grease (0.05-0.1); grows with wear")),
    _E("position_periodic_friction", "friction",
       "sum_k F_k sin(k theta_m + rho_k) sgn(omega_m), orders k = 1..4 of the WG angle.", True, False,
       F1=(0.08, "N*m", "order-1 amplitude"), F2=(0.12, "N*m", "order-2 amplitude"),
       F3=(0.0, "N*m", "order-3 amplitude"), F4=(0.0, "N*m", "order-4 amplitude"),
       order=(0.0, "-", "if > 0 keep only this order (e.g. 2), using its F_k or, if that is 0, 0.1 N*m")),
    _E("bearing_load_friction", "friction",
       "WG-bearing friction proportional to the bearing load: mu_bb r_b |F_b| sgn(omega_m).", True, False,
       mu_bb=(0.0015, "-", "equivalent WG ball-bearing friction coefficient")),
    # ---- transmission --------------------------------------------------------------------
    _E("nonlinear_stiffness", "transmission",
       "Law choice (slot torsion = three_slope): catalogue three-slope torsion law K1/K2/K3 (T1, T2) of the "
       "output, realised in the mesh spring; no torsion choice on: linear mesh spring at the K3 slope.", True, False,
       slot="torsion",
       K1=(5.6e5, "N*m/rad", "output stiffness 0..T1"), K2=(9.2e5, "N*m/rad", "T1..T2"),
       K3=(1.0e6, "N*m/rad", "above T2 (also the linear stiffness of the baseline)"),
       T1=(245.0, "N*m", "first break torque"), T2=(900.0, "N*m", "second break torque")),
    _E("cubic_stiffness", "transmission",
       "Law choice (slot torsion = cubic): hardening mesh spring T = K1 w + K3c w^3 in the mesh twist w "
       "(output rad), in series with the linear flexspline and WG-bearing compliances (their share "
       "at nonlinear_stiffness.K3).", False, False, slot="torsion",
       K1=(5.6e5, "N*m/rad", "output low-torque stiffness (as the catalogue K1)"),
       K3c=(1.0e11, "N*m/rad^3", "cubic coefficient of the mesh spring (output angle)")),
    _E("deadzone_stiffness", "transmission",
       "Law choice (slot torsion = deadzone): linear torsion at K3 with a dead zone (lost motion) of total "
       "width width_arcmin at the output, zero mesh force inside it (softplus corners of relative width "
       "smooth); adds to the wear backlash.", False, False, slot="torsion",
       width_arcmin=(1.0, "arcmin", "total dead-zone width at the output (lost motion)"),
       smooth=(0.02, "-", "corner width / dead-zone width")),
    _E("hysteresis", "transmission",
       "Bouc-Wen (n = 1, beta = gamma) internal state z_h in F_FS; z_max solved so the zero-torque loop width "
       "at +-T_rated equals loss_arcmin at the output.", True, False,
       loss_arcmin=(0.8, "arcmin", "hysteresis loss (catalogue ~1 for ratio >= 80; 0.8 is the most A_ratio = 4 "
                    "reaches with the 25 us step stable)"),
       A_ratio=(4.0, "-", "Bouc-Wen A / k_FS (pre-sliding stiffness ratio)"),
       exact_step=(0.0, "-", "z_h integration: 0 = explicit Euler (the default plant's recorded bags; rings up "
                   "and can diverge while the mesh is inside a backlash dead zone), 1 = exact step at the "
                   "updated flexspline speed (stable at any speed; the families use it; docs/FAMILIES.md)")),
    _E("backlash", "transmission",
       "Smoothed dead zone g(.; j) in the mesh, j = max(0, h+ + h- - 2 delta_0)/cos(alpha) + j0 "
       "(appears with wear once the preload delta_0 is consumed).", True, False,
       j0=(0.0, "m", "extra assembly backlash at r_m"),
       smooth=(0.05, "-", "softplus width / j")),
    _E("kinematic_error_harmonic", "transmission",
       "theta_KE = sum_{k=1,2,4} A_k sin(k theta_m + psi_k) + sum_{q=1,2} B_q sin(q theta_f + chi_q); "
       "A2 = A2(h) (1 + a_T |T|/T_rated).", True, False,
       A2=(4.0e-5, "rad", "order-2 amplitude when new (8 arcsec)"),
       A1_ratio=(0.3, "-", "A1/A2"), A4_ratio=(0.2, "-", "A4/A2"),
       a_T=(0.3, "-", "load dependence of A2"),
       B1=(1.0e-4, "rad", "output order-1 (pitch error)"), B2=(4.0e-5, "rad", "output order-2"),
       order=(0.0, "-", "if > 0 keep only this WG order (1, 2 or 4) and no B terms")),
    _E("position_dependent_stiffness", "transmission",
       "Mesh stiffness k_m (1 + eps cos(2 theta_m + psi)) (teeth in contact vary with the WG lobes).",
       True, False, eps=(0.08, "-", "relative modulation (0.05-0.15)")),
    # ---- motor ---------------------------------------------------------------------------
    _E("cogging_torque", "motor", "T_cog = C1 sin(N_c theta_m + .) + C2 sin(2 N_c theta_m + .), "
       "N_c = LCM(slots, poles) = 60 (12 slots / 10 poles).", True, False,
       C1=(0.20, "N*m", "fundamental (~1.3 % of rated motor torque)"),
       C2=(0.05, "N*m", "second harmonic"), N_c=(60.0, "-", "cogging order")),
    _E("current_ripple", "motor", "T_e = k_t i_q (1 + r6 cos(6 p theta_m + .) + r12 cos(12 p theta_m + .)).",
       True, False, r6=(0.015, "-", "6th electrical harmonic"), r12=(0.004, "-", "12th")),
    _E("motor_thermal_drift", "motor",
       "R(T_w) = R_0 (1 + alpha_R (T_w - 20)), psi_m(T_w) = psi_m0 (1 - alpha_psi (T_w - 20)); the drive "
       "keeps its nominal k_t (the logged tau_m = k_t,nom i_q).", True, False,
       alpha_R=(0.00393, "1/K", "copper"), alpha_psi=(0.0011, "1/K", "NdFeB")),
    _E("position_periodic_torque", "motor",
       "Direction-independent P_k sin(k theta_m + phi_k), k = 1, 2 (WG eccentricity / unbalance).",
       True, False, P1=(0.05, "N*m", "order 1"), P2=(0.0, "N*m", "order 2")),
    # ---- load / thermal ------------------------------------------------------------------
    _E("aero_gusts", "load", "Band-limited (0.1-5 Hz) random hinge moment T_ext added to the profile's.",
       True, True, sigma=(1.0, "-", "scale on the profile's gust level")),
    _E("self_heating", "thermal",
       "Copper losses heat the winding node, mechanical losses the gearbox node (else both stay at start).",
       True, True),
    # ---- degradation ---------------------------------------------------------------------
    _E("meshing_wear", "degradation",
       "Flank wear h+/h- maps to k_m (1 - h/t0)^3 / (1 + kappa_n h/h_fail), A2 + kappa_KE h, "
       "mu_c (1 + kappa_mu h/h_fail), T_C (1 + kappa_TC h/h_fail) and backlash j(h).", True, True,
       kappa_n=(0.35, "-", "loss of effective teeth in contact at h_fail"),
       kappa_KE=(6.0, "rad/m", "A2 growth per m of wear (0.5/r_m)"),
       kappa_mu=(1.0, "-", "mesh friction growth at h_fail"),
       kappa_TC=(0.3, "-", "no-load running torque growth at h_fail")),
    _E("flexspline_stiffness_loss", "degradation",
       "Flexspline fatigue: k_FS (1 - loss) (fleet: grows by rate per mission after onset).", False, False,
       loss=(0.0, "-", "fraction of k_FS lost in this mission"),
       onset=(100.0, "mission", "fleet: mission index where the loss starts"),
       rate=(0.002, "1/mission", "fleet: growth of loss per mission")),
    _E("lubrication_loss", "degradation",
       "Grease degradation: friction x (1 + severity), k_D x (1 + 4 severity).", False, False,
       severity=(0.0, "-", "in this mission"),
       onset=(100.0, "mission", "fleet: onset"), rate=(0.005, "1/mission", "fleet: growth per mission")),
    # ---- sensors -------------------------------------------------------------------------
    _E("encoder_quantisation", "sensor", "Motor and load encoders quantised to 2 pi / 2^bits.", True, True,
       bits_m=(18.0, "bit", "motor encoder"), bits_f=(20.0, "bit", "load (output) encoder")),
    _E("sensor_noise", "sensor", "White noise on current, torque, speeds and temperatures.", True, True,
       sigma_i=(0.05, "A", "phase-current measurement"), sigma_Q=(3.0, "N*m", "output torque sensor"),
       sigma_omega_m=(0.02, "rad/s", "motor speed"), sigma_omega_f=(2e-4, "rad/s", "output speed"),
       sigma_T=(0.1, "K", "temperature sensors")),
    _E("torque_sensor_bandwidth", "sensor",
       "Output torque sensor with first-order dynamics: Q_meas' = 2 pi f_c (Q_red - Q_meas), before the noise.",
       False, False, f_c=(200.0, "Hz", "sensor bandwidth")),
    _E("drive_speed_estimate", "sensor",
       "Logged speeds are the drive's own estimate, not the true speed: the quantised encoder angle "
       "differentiated at the log rate and low-passed (first order), hence lagged and quantisation-noisy "
       "(replaces sensor_noise's speed noise).", False, False,
       f_c_m=(100.0, "Hz", "motor-speed estimator bandwidth"), f_c_f=(30.0, "Hz", "output-speed estimator bandwidth")),
    _E("stamp_jitter", "sensor",
       "Sample stamps carry timing jitter: header.stamp = t_k + e_k, e_k ~ N(0, sigma) clipped to +-0.45 "
       "of the period (order kept); the signals are taken at the nominal instants.", False, False,
       sigma=(5e-5, "s", "jitter standard deviation")),
    _E("dropouts", "sensor", "Missing joint-state samples (gaps) and NaN sensor faults.", False, False,
       rate=(0.5, "1/s", "gap starts per second"), mean_len=(5.0, "samples", "mean gap length"),
       nan_rate=(0.2, "1/s", "NaN burst starts per second"), nan_len=(3.0, "samples", "NaN burst length")),
)}


#: Law slots: slot -> choice -> effects it switches on. Choosing one switches every effect of the slot
#: off first (``EffectSet.with_law``, CLI ``--law SLOT=CHOICE``); ``derived`` refuses two on at once.
#: The hysteresis (Bouc-Wen) effect is independent of the torsion slot (the default plant has the
#: three-slope curve *and* the hysteresis); the ``bouc_wen`` choice is the linear spring with it,
#: ``linear`` / ``deadzone`` the linear spring (with a dead zone) without it.
LAW_SLOTS: dict[str, dict[str, tuple[str, ...]]] = {
    "friction_transition": {"hard_sign": (), "tanh": ("smooth_friction",), "lugre": ("lugre_friction",)},
    "torsion": {"three_slope": ("nonlinear_stiffness",), "linear": (), "cubic": ("cubic_stiffness",),
                "deadzone": ("deadzone_stiffness",), "bouc_wen": ("hysteresis",)},
}
#: Docs of the implicit choices (no effect of the slot on).
LAW_DOCS = {
    ("friction_transition", "hard_sign"): "tanh(omega_m/coulomb_friction.eps_v), eps_v = 0.02 rad/s: a "
                                          "near-hard sign (today's default)",
    ("torsion", "linear"): "linear mesh spring at nonlinear_stiffness.K3",
}


def slot_members(slot: str) -> tuple[str, ...]:
    """Effects that belong to a law slot (at most one may be on); ``hysteresis`` is not one of them."""
    return tuple(n for n, e in REGISTRY.items() if e.slot == slot)


def _parse_bool(text: str, where: str) -> bool:
    t = str(text).strip().lower()
    if t in ("on", "1", "true", "yes"):
        return True
    if t in ("off", "0", "false", "no"):
        return False
    raise ValueError(f"{where}: {text!r} is not on/off")


class EffectSet:
    """Which effects are on, with their parameters (defaults + overrides)."""

    def __init__(self, on: Mapping[str, bool], params: Mapping[str, Mapping[str, float]] | None = None):
        unknown = set(on) - set(REGISTRY)
        if unknown:
            raise KeyError(f"unknown effect(s) {sorted(unknown)}; see `hdphm sim effects`")
        self.on = {n: bool(on.get(n, False)) for n in REGISTRY}
        self.params: dict[str, dict[str, float]] = {n: {k: v[0] for k, v in e.params.items()}
                                                    for n, e in REGISTRY.items()}
        self.overridden: set[tuple[str, str]] = set()
        for n, kv in (params or {}).items():
            for k, v in kv.items():
                self.set_param(n, k, v)

    # ---- constructors --------------------------------------------------------------------
    @classmethod
    def default(cls) -> "EffectSet":
        """Every effect at its realistic default."""
        return cls({n: e.default_on for n, e in REGISTRY.items()})

    @classmethod
    def baseline(cls) -> "EffectSet":
        """What a basic twin declares (see the module docstring)."""
        return cls({n: e.baseline for n, e in REGISTRY.items()})

    @classmethod
    def preset(cls, name: str) -> "EffectSet":
        if name == "default":
            return cls.default()
        if name == "baseline":
            return cls.baseline()
        if name == "ideal":  # baseline without sensor imperfections and gusts
            return cls.baseline().with_off("encoder_quantisation", "sensor_noise", "aero_gusts")
        raise KeyError(f"unknown effect preset {name!r} (default, baseline, ideal)")

    def copy(self) -> "EffectSet":
        new = EffectSet(self.on)
        new.params = {n: dict(kv) for n, kv in self.params.items()}
        new.overridden = set(self.overridden)
        return new

    def with_on(self, *names: str) -> "EffectSet":
        return self._with(names, True)

    def with_off(self, *names: str) -> "EffectSet":
        return self._with(names, False)

    def _with(self, names: Iterable[str], value: bool) -> "EffectSet":
        new = self.copy()
        for n in names:
            if n not in REGISTRY:
                raise KeyError(f"unknown effect {n!r}; see `hdphm sim effects`")
            new.on[n] = value
        return new

    def with_law(self, slot: str, choice: str) -> "EffectSet":
        """Choose the law of ``slot`` (``LAW_SLOTS``): every effect of the slot off, the choice's on."""
        if slot not in LAW_SLOTS:
            raise KeyError(f"unknown law slot {slot!r}; slots: {sorted(LAW_SLOTS)}")
        if choice not in LAW_SLOTS[slot]:
            raise KeyError(f"law slot {slot!r} has no choice {choice!r}; choices: {sorted(LAW_SLOTS[slot])}")
        new = self.with_off(*slot_members(slot))
        if slot == "torsion" and choice in ("linear", "deadzone"):  # a plain spring (with a dead zone): no hysteresis
            new = new.with_off("hysteresis")
        return new.with_on(*LAW_SLOTS[slot][choice])

    def law(self, slot: str) -> str:
        """The chosen law of ``slot`` (ValueError if two of its effects are on)."""
        on = [n for n in slot_members(slot) if self.on[n]]
        if len(on) > 1:
            raise ValueError(f"law slot {slot}: effects {on} are all on; choose one (--law {slot}=CHOICE)")
        if on:
            return next(c for c, names in LAW_SLOTS[slot].items() if names and names[0] == on[0])
        if slot == "torsion":
            return "bouc_wen" if self.on["hysteresis"] else "linear"
        return "hard_sign"

    def with_params(self, **kw: float) -> "EffectSet":
        """``with_params(**{"stribeck_friction.ratio": 1.5})``."""
        new = self.copy()
        for key, v in kw.items():
            n, _, k = key.partition(".")
            new.set_param(n, k, v)
        return new

    def set_param(self, name: str, key: str, value: Any) -> None:
        if name not in REGISTRY:
            raise KeyError(f"unknown effect {name!r} in parameter {name}.{key}")
        if key not in REGISTRY[name].params:
            raise KeyError(f"effect {name!r} has no parameter {key!r}; it has {sorted(REGISTRY[name].params)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"parameter {name}.{key} = {value!r} is not a number") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError(f"parameter {name}.{key} = {value!r} is not finite")
        self.params[name][key] = v
        self.overridden.add((name, key))

    def apply_cli(self, effects: Iterable[str] = (), params: Iterable[str] = (),
                  laws: Iterable[str] = ()) -> "EffectSet":
        """Apply ``SLOT=CHOICE`` laws, then ``NAME=on|off`` and ``NAME.KEY=VALUE`` strings (CLI syntax)."""
        new = self.copy()
        for s in laws:
            slot, sep, choice = s.partition("=")
            if not sep:
                raise ValueError(f"--law {s!r}: expected SLOT=CHOICE ({_laws_hint()})")
            try:
                new = new.with_law(slot.strip(), choice.strip())
            except KeyError as e:
                raise KeyError(f"--law {s!r}: {e.args[0]}") from None
        for s in effects:
            n, sep, v = s.partition("=")
            if not sep:
                raise ValueError(f"--effect {s!r}: expected NAME=on|off")
            n = n.strip()
            if n not in REGISTRY:
                raise KeyError(f"--effect {s!r}: unknown effect {n!r}; see `hdphm sim effects`")
            new.on[n] = _parse_bool(v, f"--effect {s}")
        for s in params:
            k, sep, v = s.partition("=")
            n, dot, key = k.strip().partition(".")
            if not sep or not dot:
                raise ValueError(f"--param {s!r}: expected NAME.KEY=VALUE")
            new.set_param(n, key, v)
        return new

    def p(self, name: str, key: str) -> float:
        return self.params[name][key]

    def is_on(self, name: str) -> bool:
        return self.on[name]

    def to_json_dict(self) -> dict[str, dict[str, Any]]:
        return {n: {"on": self.on[n], **self.params[n]} for n in REGISTRY}

    def __repr__(self) -> str:
        return "EffectSet(on=" + ",".join(n for n in REGISTRY if self.on[n]) + ")"


def _laws_hint() -> str:
    return "; ".join(f"{s}: {'|'.join(c)}" for s, c in LAW_SLOTS.items())


def laws_table(markdown: bool = False) -> str:
    """The law slots and their choices (first part of ``hdphm sim effects``)."""
    lines = []
    if markdown:
        lines += ["| law slot | choice | effects switched on | law |", "|---|---|---|---|"]
    else:
        lines.append("Law slots (--law SLOT=CHOICE; a choice switches the slot's other effects off):")
    for slot, choices in LAW_SLOTS.items():
        for choice, names in choices.items():
            doc = LAW_DOCS.get((slot, choice)) or "; ".join(REGISTRY[n].doc.split(": ", 1)[-1] for n in names)
            if choice == "bouc_wen":
                doc = "linear mesh spring + Bouc-Wen hysteresis (the hysteresis effect)"
            if markdown:
                doc = doc.replace("|", "\\|")
                lines.append(f"| {slot} | `{choice}` | {', '.join(f'`{n}`' for n in names) or '-'} | {doc} |")
            else:
                lines.append(f"  {slot}={choice:12s} effects on: {','.join(names) or '-'}")
    return "\n".join(lines)


def effects_table(markdown: bool = False) -> str:
    """Human-readable listing of the registry (``hdphm sim effects``)."""
    lines = [laws_table(markdown), ""]
    if markdown:
        lines.append("| effect | category | default | baseline | parameters (default, unit) |")
        lines.append("|---|---|---|---|---|")
    for e in REGISTRY.values():
        ps = ", ".join(f"{k}={v[0]:g} {v[1]}" for k, v in e.params.items())
        if markdown:
            lines.append(f"| `{e.name}` | {e.category} | {'on' if e.default_on else 'off'} | "
                         f"{'yes' if e.baseline else 'no'} | {ps} |")
        else:
            lines.append(f"{e.name:32s} {e.category:13s} default={'on ' if e.default_on else 'off'} "
                         f"baseline={'yes' if e.baseline else 'no '}" + (f" law slot={e.slot}" if e.slot else ""))
            lines.append(f"    {e.doc}")
            for k, v in e.params.items():
                lines.append(f"    {e.name}.{k} = {v[0]:g} [{v[1]}]  {v[2]}")
    return "\n".join(lines)


def dumps(effects: EffectSet, params: Mapping[str, Any]) -> str:
    return json.dumps({"effects": effects.to_json_dict(), "params": dict(params)}, sort_keys=True)
