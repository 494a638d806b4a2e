"""Three-body harmonic-drive physics of the twin: the residuals r1..r4, in ONE place.

The model (``../shared/PHYSICS.md`` section 1, paper eq. 3) has four bodies:
wave generator + rotor (theta_m), flexspline radial (x_FS), flexspline
tangential (y_FS) and circular spline (theta_f)::

    r1 = Q_res - F_b r_b - J_WG theta_m''          WG torque balance       [N*m]
    r2 = F_b - F_mx - m_FSx x_FS''                 FS radial               [N]
    r3 = -F_FS - F_my - m_FSy y_FS''               FS tangential / torsion [N]
    r4 = F_m r_m - Q_red - Q_out - J_CS theta_f''  CS torque balance       [N*m]

(F_m = F_my; ``Q_out`` is the sum of output-side extra terms, zero unless
discovery declared one.) Every function here is written against an *array
namespace* ``xp`` (``numpy`` or ``torch``): the same code evaluates numpy
arrays (tests, discovery, onboard stand-in) and torch tensors (the PINN loss),
so there is exactly one place per equation.

Constitutive closure (PHYSICS.md 1.2, the "equivalent wedge"), used when the
twin declares ``linear_stiffness``; deflections in m::

    mu_g    = r_m / (N r_b)
    u       = x_FS - r_b theta_m          (the small part of the unwrapped x_FS)
    delta_b = r_b theta_m - x_FS = -u
    delta_m = mu_g x_FS + y_FS - r_m theta_f = mu_g u + y_FS - r_m phi,
              phi = theta_f - theta_m / N  (output-side twist, rad)
    F_b     = k_b delta_b + c_b delta_b'
    F_m     = k_m delta_m + c_m delta_m'
    F_FS    = k_FS y_FS + c_FS y_FS'
    F_mx    = mu_g F_my + mu_c |F_my| sgn_eps(omega_m)    (mu_c only with ``mesh_friction``)

Input-side friction (PHYSICS.md 2.5) of the declared effects is removed from
the motor torque: ``Q_res = tau_m - T_fric_in - sum(extra input terms)``.

The twin never imports the plant (``hd_sim``): its numbers come from
``default_params.yaml`` (PHYSICS.md's own estimates scaled to size 65), from the bag
metadata (N, k_t) and from recalibration.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .terms import CATALOG_NAMES

#: Canonical effect names (PHYSICS.md section 7) plus the structural terms the
#: three-body model itself is built of. Discovery may add names outside this
#: tuple: they are kept and reported, and only ``extra_terms`` give them maths.
CATALOG_EFFECTS = CATALOG_NAMES
STRUCTURAL_EFFECTS = ("inertia", "linear_stiffness", "structural_damping", "mesh_friction")
#: Effects this module gives equations to (others are accepted as names only).
IMPLEMENTED_EFFECTS = STRUCTURAL_EFFECTS + (
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "temperature_dependent_friction",
    "load_dependent_friction",
)
DEFAULT_EFFECTS = (
    "inertia",
    "linear_stiffness",
    "structural_damping",
    "mesh_friction",
    "coulomb_friction",
    "viscous_friction",
)

DEFAULT_PARAMS_PATH = Path(__file__).with_name("default_params.yaml")

#: (lower, upper) physically meaningful bounds, SI; values outside are refused.
_BOUNDS: dict[str, tuple[float, float]] = {
    "N": (1.0, 1000.0),
    "k_t": (1e-3, 50.0),
    "r_b": (1e-3, 1.0),
    "r_m": (1e-3, 1.0),
    "J_WG": (0.0, 10.0),
    "J_rotor": (0.0, 10.0),
    "J_CS": (0.0, 1e3),
    "m_FSx": (0.0, 1e3),
    "m_FSy": (0.0, 1e3),
    "k_b": (1.0, 1e13),
    "k_m": (1.0, 1e13),
    "k_FS": (1.0, 1e13),
    "c_b": (0.0, 1e9),
    "c_m": (0.0, 1e9),
    "c_FS": (0.0, 1e9),
    "mu_c": (0.0, 1.0),
    "T_C": (0.0, 1e3),
    "T_S": (0.0, 1e3),
    "omega_s": (1e-6, 1e4),
    "stribeck_delta": (0.1, 5.0),
    "b_visc": (0.0, 1e2),
    "eps_omega": (1e-6, 1e3),
    "c_L": (0.0, 0.5),
    "T_ref": (-100.0, 300.0),
    "beta_visc": (0.0, 1.0),
    "a_TC": (0.0, 1.0),
}


@dataclass
class TwinParams:
    """Physical parameters of the twin, SI units, paper nomenclature.

    Geometry / inertia: ``N`` [-] reduction ratio (motor turns per output
    turn), ``k_t`` [N*m/A], ``r_b`` [m] bearing-force radius, ``r_m`` [m]
    meshing-force radius, ``J_WG`` [kg*m^2] wave-generator inertia,
    ``J_rotor`` [kg*m^2] motor rotor rigidly coupled to the WG, ``J_CS``
    [kg*m^2] circular spline + output shaft up to the torque measurement,
    ``m_FSx``/``m_FSy`` [kg] flexspline equivalent radial / tangential masses.
    Stiffness / damping: ``k_b``, ``k_m``, ``k_FS`` [N/m], ``c_b``, ``c_m``,
    ``c_FS`` [N*s/m]; ``mu_c`` [-] flank sliding-friction coefficient.
    Input friction (PHYSICS.md 2.5): ``T_C`` [N*m] Coulomb, ``T_S`` [N*m]
    static (Stribeck), ``omega_s`` [rad/s] Stribeck velocity,
    ``stribeck_delta`` [-], ``b_visc`` [N*m*s/rad] viscous at ``T_ref``,
    ``eps_omega`` [rad/s] width of the regularised sign, ``c_L`` [-]
    load-dependent share (input N*m per output N*m), ``T_ref`` [degC],
    ``beta_visc`` [1/K] viscosity-temperature coefficient
    (b(T) = b_visc exp(-beta_visc (T - T_ref))), ``a_TC`` [1/K] Coulomb rise per
    kelvin below T_ref.
    """

    N: float = 101.0
    k_t: float = 1.2
    r_b: float = 0.070
    r_m: float = 0.0826
    J_WG: float = 4.9e-3
    J_rotor: float = 2.0e-3
    J_CS: float = 0.12
    m_FSx: float = 0.05
    m_FSy: float = 1.3
    k_b: float = 1.0e5
    k_m: float = 2.9e8
    k_FS: float = 4.9e8
    c_b: float = 4.2
    c_m: float = 1.2e3
    c_FS: float = 1.5e3
    mu_c: float = 0.0029
    T_C: float = 1.1
    T_S: float = 1.45
    omega_s: float = 5.0
    stribeck_delta: float = 1.0
    b_visc: float = 6.0e-4
    eps_omega: float = 0.05
    c_L: float = 1.0e-3
    T_ref: float = 25.0
    beta_visc: float = 0.03
    a_TC: float = 0.01
    #: Free-text provenance of the numbers (kept in config.json).
    source: str = "default"
    notes: dict[str, str] = field(default_factory=dict)

    # ---- derived -----------------------------------------------------------
    @property
    def mu_g(self) -> float:
        """Mesh wedge slope r_m / (N r_b) [-] (ideal kinematics theta_f = theta_m / N)."""
        return self.r_m / (self.N * self.r_b)

    @property
    def J_in(self) -> float:
        """Input-side inertia on theta_m: J_WG + J_rotor [kg*m^2]."""
        return self.J_WG + self.J_rotor

    @property
    def K_out(self) -> float:
        """Output torsional stiffness of the series springs [N*m/rad] (PHYSICS.md 1.2)."""
        return self.r_m**2 / (1.0 / self.k_m + 1.0 / self.k_FS + self.mu_g**2 / self.k_b)

    # ---- I/O ---------------------------------------------------------------
    def validate(self, where: str = "twin parameters") -> "TwinParams":
        """Refuse NaN and physically absurd values with a message naming the parameter."""
        for name, (lo, hi) in _BOUNDS.items():
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool):
                raise ValueError(f"{where}: {name} must be a number, got {type(v).__name__} {v!r}")
            if not math.isfinite(v) or v < lo or v > hi:
                raise ValueError(f"{where}: {name} = {v!r} outside the physically meaningful range [{lo:g}, {hi:g}] (SI)")
        if self.T_S < self.T_C and self.T_S > 0:
            raise ValueError(f"{where}: static friction T_S = {self.T_S} is below Coulomb T_C = {self.T_C}")
        return self

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["mu_g"] = self.mu_g
        d["K_out"] = self.K_out
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str = "twin parameters") -> "TwinParams":
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected a mapping of parameter names to numbers, got {type(d).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        derived = {"mu_g", "K_out"}
        unknown = set(d) - names - derived
        if unknown:
            raise ValueError(f"{where}: unknown parameter(s) {sorted(unknown)}; known: {sorted(names)}")
        kw = {}
        for k, v in d.items():
            if k in derived:
                continue
            if k in ("source",):
                kw[k] = str(v)
            elif k == "notes":
                kw[k] = {str(a): str(b) for a, b in (v or {}).items()}
            else:
                try:
                    kw[k] = float(v)
                except (TypeError, ValueError):
                    raise ValueError(f"{where}: parameter {k} = {v!r} is not a number") from None
        return cls(**kw).validate(where)

    @classmethod
    def from_yaml(cls, path: str | Path | None = None) -> "TwinParams":
        """Load parameters from a YAML file (default: the shipped ``default_params.yaml``)."""
        path = Path(path) if path is not None else DEFAULT_PARAMS_PATH
        try:
            raw = yaml.safe_load(path.read_text())
        except FileNotFoundError:
            raise ValueError(f"{path}: twin parameter file not found") from None
        except yaml.YAMLError as e:
            raise ValueError(f"{path}: not valid YAML ({e})") from None
        if isinstance(raw, dict) and "params" in raw:
            raw = raw["params"]
        return cls.from_dict(raw, where=str(path))

    def with_meta(self, gear_ratio: float | None = None, torque_constant: float | None = None) -> "TwinParams":
        """Copy with N and k_t taken from bag metadata (the bag is the truth for these)."""
        p = dataclasses.replace(self)
        if gear_ratio is not None:
            p.N = float(gear_ratio)
        if torque_constant is not None:
            p.k_t = float(torque_constant)
        return p.validate("twin parameters with bag metadata")


def check_effects(effects: list[str] | tuple[str, ...]) -> list[str]:
    """Validate a declared-effects list (strings, no duplicates); returns it as a list."""
    if isinstance(effects, str) or not all(isinstance(e, str) and e for e in effects):
        raise ValueError(f"declared effects must be a list of non-empty names, got {effects!r}")
    if len(set(effects)) != len(effects):
        raise ValueError(f"declared effects contain duplicates: {effects!r}")
    return list(effects)


# ---- elementary functions (array-namespace generic) ------------------------
def sgn_eps(xp, w, eps: float):
    """Regularised sign tanh(w / eps) [-]."""
    return xp.tanh(w / eps)


#: Input-friction effects with an equation here whose parameters are defaults unless recalibrated; when an
#: extra term carries one of them (discovery declares a found effect and writes its identified term under the
#: effect's name), the term alone evaluates it (:func:`equation_effects`).
TERM_CARRIED_EFFECTS = ("stribeck_friction", "temperature_dependent_friction", "load_dependent_friction")


def equation_effects(effects, extra_terms=()) -> list[str]:
    """The declared effects this module evaluates with its own equations, given the model's extra terms.

    An effect in :data:`TERM_CARRIED_EFFECTS` that an extra term is named after is left to that term: its
    equation here would add a second, default-parameter copy of the same effect (discovery writes both the
    declared name, so the model records the effect, and the identified term). Every other effect is kept."""
    carried = {t.get("name") for t in extra_terms if isinstance(t, dict)} & set(TERM_CARRIED_EFFECTS)
    return [e for e in effects if e not in carried]


def input_friction(xp, p: TwinParams, effects, omega_m, temperature=None, Q_red=None):
    """Input-side (motor-referred) friction torque of the declared effects [N*m].

    ``omega_m`` rad/s, ``temperature`` degC (gearbox/grease; None or NaN-free
    array), ``Q_red`` N*m (the output torque, for ``load_dependent_friction``).
    Effects used: coulomb_friction, stribeck_friction, viscous_friction,
    temperature_dependent_friction (scales both b and T_C), load_dependent_friction.
    """
    s = sgn_eps(xp, omega_m, p.eps_omega)
    T_f = omega_m * 0.0
    temp_dep = "temperature_dependent_friction" in effects and temperature is not None
    dT = (temperature - p.T_ref) if temp_dep else None
    if "coulomb_friction" in effects or "stribeck_friction" in effects:
        T_C = p.T_C
        coul = T_C * (1.0 - p.a_TC * dT) if temp_dep else T_C + 0.0 * omega_m
        if "stribeck_friction" in effects:
            coul = coul + (p.T_S - p.T_C) * xp.exp(-((xp.abs(omega_m) / p.omega_s) ** p.stribeck_delta))
        T_f = T_f + coul * s
    if "viscous_friction" in effects or temp_dep:
        b = p.b_visc * xp.exp(-p.beta_visc * dT) if temp_dep else p.b_visc
        T_f = T_f + b * omega_m
    if "load_dependent_friction" in effects and Q_red is not None:
        T_f = T_f + p.c_L * xp.abs(Q_red) * s
    return T_f


def q_res(xp, p: TwinParams, effects, tau_m, omega_m, temperature=None, Q_red=None, extra_in=None):
    """Resultant input torque on the WG, Q_res = tau_m - T_fric,in - extra input terms [N*m]."""
    out = tau_m - input_friction(xp, p, effects, omega_m, temperature, Q_red)
    if extra_in is not None:
        out = out - extra_in
    return out


def closure_forces(xp, p: TwinParams, effects, u, u_d, y, y_d, phi, phi_d, omega_m):
    """Internal forces from the deflections by the constitutive closure [N].

    ``u`` = x_FS - r_b theta_m [m] and ``y`` = y_FS [m] (the network's latent
    states) with their time derivatives ``u_d``, ``y_d`` [m/s]; ``phi`` =
    theta_f - theta_m / N [rad] and ``phi_d`` [rad/s] from the measurements;
    ``omega_m`` [rad/s] for the flank-friction direction.
    Returns (F_b, F_mx, F_my, F_FS).
    """
    if "linear_stiffness" not in effects:
        raise ValueError("the twin's constitutive closure needs the declared effect 'linear_stiffness'")
    damp = "structural_damping" in effects
    mu_g = p.mu_g
    d_b, d_b_d = -u, -u_d
    d_m = mu_g * u + y - p.r_m * phi
    d_m_d = mu_g * u_d + y_d - p.r_m * phi_d
    F_b = p.k_b * d_b + (p.c_b * d_b_d if damp else 0.0)
    F_my = p.k_m * d_m + (p.c_m * d_m_d if damp else 0.0)
    F_FS = p.k_FS * y + (p.c_FS * y_d if damp else 0.0)
    return F_b, mesh_radial_force(xp, p, effects, F_my, omega_m), F_my, F_FS


def mesh_radial_force(xp, p: TwinParams, effects, F_my, omega_m):
    """Radial mesh force F_mx [N] from the tangential F_my [N]: wedge mu_g F_my (+ flank friction)."""
    F_mx = p.mu_g * F_my
    if "mesh_friction" in effects:
        F_mx = F_mx + p.mu_c * xp.abs(F_my) * sgn_eps(xp, omega_m, p.eps_omega)
    return F_mx


def residuals(xp, p: TwinParams, effects, *, Q_res, Q_red, theta_m_dd, theta_f_dd, x_FS_dd, y_FS_dd,
              F_b, F_mx, F_my, F_FS, Q_out=None):
    """The three-body residuals (r1 [N*m], r2 [N], r3 [N], r4 [N*m]); zero for a perfect model.

    Inertia terms enter only when ``inertia`` is declared. ``Q_out`` [N*m] is
    the sum of output-side extra terms (discovery), subtracted in r4.
    """
    inert = "inertia" in effects
    r1 = Q_res - F_b * p.r_b - (p.J_in * theta_m_dd if inert else 0.0)
    r2 = F_b - F_mx - (p.m_FSx * x_FS_dd if inert else 0.0)
    r3 = -F_FS - F_my - (p.m_FSy * y_FS_dd if inert else 0.0)
    r4 = F_my * p.r_m - Q_red - (p.J_CS * theta_f_dd if inert else 0.0)
    if Q_out is not None:
        r4 = r4 - Q_out
    return r1, r2, r3, r4


def residual_scales(p: TwinParams, Q_scale: float) -> np.ndarray:
    """Characteristic magnitudes of r1..r4 for an output-torque scale ``Q_scale`` [N*m].

    r1 ~ Q/N (input torque), r2 ~ mu_g Q / r_m (radial force), r3 ~ Q / r_m
    (mesh force), r4 ~ Q. Used to make the physics loss dimensionless when the
    adaptive scaling is off, and to report it comparably across epochs.
    """
    Q = max(float(Q_scale), 1e-9)
    return np.array([Q / p.N, p.mu_g * Q / p.r_m, Q / p.r_m, Q], dtype=float)


def quasi_static_Q_red(p: TwinParams, effects, tau_m, omega_m, temperature=None, theta_m_dd=None, theta_f_dd=None):
    """Output torque the declared physics alone predicts from the input side [N*m] (numpy).

    Eliminates the stiff internal states (quasi-static FS, no flank friction):
    Q_red = N (Q_res - J_in theta_m'') - J_CS theta_f''. A transparent physics
    baseline for the twin's metrics; load-dependent friction is not used (it
    would need Q_red itself).
    """
    qr = q_res(np, p, [e for e in effects if e != "load_dependent_friction"], tau_m, omega_m, temperature)
    inert = "inertia" in effects
    if inert and theta_m_dd is not None:
        qr = qr - p.J_in * theta_m_dd
    out = p.N * qr
    if "mesh_friction" in effects:
        out = out / (1.0 + p.mu_c / p.mu_g * np.sign(omega_m) * np.sign(out))
    if inert and theta_f_dd is not None:
        out = out - p.J_CS * theta_f_dd
    return out
