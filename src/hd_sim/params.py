"""Actuator parameters: nominal size-65 strain-wave-gear flap EMA, population spread, wear mapping.

Size chosen: a **size-65 cup-type harmonic drive, Z_FS/Z_CS = 200/202, FS
fixed, CS output, N = 101** (PHYSICS.md 1.3), so that the paper's output
torques of about +-3000 N*m sit near its repeated peak torque. Catalogue
stiffness, torques and friction of size 32 were scaled by (65/32)^3 ~ 8.4
(torque capacity and torsional stiffness scale with the cube of the pitch
diameter), inertia roughly by size^5: K1/K2/K3 = 5.6e5/9.2e5/1.0e6 N*m/rad,
T1/T2 = 245/900 N*m, rated ~1200 N*m, repeated peak ~3600 N*m. The motor is
a 270 V, 5-pole-pair PMSM with k_t = 1.2 N*m/A, i_max = 45 A (~54 N*m).
All parameters are in SI; the table :data:`NOMINAL` gives value, unit and
meaning, :data:`SPREAD` the unit-to-unit variability.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

#: name -> (nominal value, unit, meaning)
NOMINAL: dict[str, tuple[float, str, str]] = {
    # gear geometry
    "Z_FS": (200, "-", "flexspline teeth"),
    "Z_CS": (202, "-", "circular-spline teeth (N = Z_CS/(Z_CS - Z_FS), FS fixed, CS output)"),
    "r_m": (0.0825, "m", "mesh (pitch) radius, size 65 ~ 6.5 in pitch diameter"),
    "r_b": (0.070, "m", "WG bearing force radius"),
    "b_face": (0.026, "m", "tooth face width"),
    "alpha_p": (math.radians(25.0), "rad", "pressure angle"),
    "n_eff": (20.0, "-", "effectively loaded teeth (new)"),
    # inertias and masses
    "J_WG_plug": (3.5e-3, "kg*m^2", "wave-generator plug"),
    "J_rotor": (2.5e-3, "kg*m^2", "motor rotor (rigidly coupled: J_WG = J_WG_plug + J_rotor)"),
    "J_CS": (0.05, "kg*m^2", "circular spline + output flange"),
    "J_L": (8.0, "kg*m^2", "flap about the hinge"),
    "m_FSx": (0.02, "kg", "flexspline radial equivalent mass (radial mode ~0.4 kHz)"),
    "m_FSy": (2.0, "kg", "flexspline tangential equivalent mass (tangential mode ~3 kHz)"),
    # compliance split at K3 (mesh / FS / bearing) and damping
    "split_mesh": (0.5, "-", "mesh share of output compliance at K3"),
    "split_FS": (0.3, "-", "flexspline share"),
    "c_b": (2.7, "N*s/m", "WG-bearing damping (zeta ~0.03 of the radial mode)"),
    "c_FS": (1.5e3, "N*s/m", "flexspline torsional damping"),
    "c_m": (5.6e4, "N*s/m", "mesh damping (load-mode zeta ~0.03)"),
    # load
    "K_aero": (4500.0, "N*m/rad", "hinge-moment stiffness q S c |C_h_delta|"),
    "c_aero": (20.0, "N*m*s/rad", "aerodynamic damping"),
    # motor and drive
    "p": (5, "-", "pole pairs"),
    "k_t": (1.2, "N*m/A", "torque constant at 20 degC (k_t = 1.5 p psi_m)"),
    "R0": (0.15, "ohm", "phase resistance at 20 degC"),
    "L": (1.5e-3, "H", "L_d = L_q"),
    "V_dc": (270.0, "V", "DC bus (V_max = V_dc/sqrt 3)"),
    "i_max": (45.0, "A", "current limit"),
    # control
    "f_i": (1000.0, "Hz", "current-loop bandwidth"),
    "f_w": (40.0, "Hz", "speed-loop bandwidth"),
    "f_p": (6.0, "Hz", "position-loop bandwidth (output encoder)"),
    "rate_max_deg": (80.0, "deg/s", "flap rate limit"),
    "f_ctrl": (5000.0, "Hz", "outer-loop sampling"),
    # thermal
    "C_w": (120.0, "J/K", "winding heat capacity (tau_w = 60 s)"),
    "R_wh": (0.5, "K/W", "winding-to-housing"),
    "C_h": (1200.0, "J/K", "gearbox/housing heat capacity (tau_h = 20 min)"),
    "R_ha": (1.0, "K/W", "housing-to-ambient"),
    # wear
    "k_D": (5.0e-18, "m^2/N", "Archard dimensional wear rate (median)"),
    "mission_hours": (140.0, "h", "operating hours one inspection mission stands for; wear acceleration "
                      "factor = mission_hours * 3600 / duration (2.5e4 for 20 s missions)"),
    "delta_0": (2.0e-6, "m", "flexspline interference preload (consumed before backlash)"),
    "h_fail": (40e-6, "m", "failure threshold on mean flank wear (lost motion ~3.5 arcmin)"),
    "T_rated": (1200.0, "N*m", "rated output torque"),
}

#: Unit-to-unit variability: name -> ("lognormal", sigma_ln) | ("uniform", lo, hi) | ("normal_rel", sigma).
SPREAD: dict[str, tuple] = {
    "k_D": ("lognormal", 0.4),
    "delta_0": ("uniform", 1.0e-6, 3.0e-6),
    "J_L": ("normal_rel", 0.10),
    "K_aero": ("normal_rel", 0.10),
    "R0": ("normal_rel", 0.03),
    "k_t": ("normal_rel", 0.02),
    "J_rotor": ("normal_rel", 0.03),
    "c_m": ("normal_rel", 0.10),
    "h_fail": ("normal_rel", 0.05),
}

#: Effect parameters that also vary from unit to unit (relative normal sigma) and phases drawn U(0, 2 pi).
EFFECT_SPREAD: dict[str, float] = {
    "coulomb_friction.T_C": 0.10, "viscous_friction.b": 0.10,
    "kinematic_error_harmonic.A2": 0.15, "load_dependent_friction.mu_flank": 0.10,
    "nonlinear_stiffness.K1": 0.05, "nonlinear_stiffness.K2": 0.05, "nonlinear_stiffness.K3": 0.05,
    "cogging_torque.C1": 0.10, "position_periodic_friction.F1": 0.20, "position_periodic_friction.F2": 0.20,
}
PHASES = ("psi1", "psi2", "psi4", "chi1", "chi2", "psi_s", "rho1", "rho2", "rho3", "rho4",
          "phi_p1", "phi_p2", "phi_c1", "phi_c2", "phi_r6", "phi_r12")


def nominal() -> dict[str, float]:
    """The nominal actuator as a flat dict (name -> value, SI), including zero phases."""
    d = {k: float(v[0]) for k, v in NOMINAL.items()}
    d.update({ph: 0.0 for ph in PHASES})
    d["actuator_id"] = "EMA-NOM"
    d["effect_scale"] = {}
    return d


def sample_population(n: int, seed: int = 0, id_prefix: str = "EMA") -> list[dict[str, Any]]:
    """``n`` actuators with parameters drawn within physically meaningful ranges (seeded).

    Returns dicts like :func:`nominal` with per-unit ``k_D`` (lognormal, sigma_ln
    0.4), preload ``delta_0`` (U 1-3 um), load and motor spread, KE / friction
    amplitude spread (``effect_scale``: relative factors on effect defaults) and
    random harmonic phases. Vectorised draws; unit i is the same whatever n.
    """
    if n < 0:
        raise ValueError(f"sample_population: n = {n} < 0")
    out = []
    for i in range(n):
        rng = np.random.default_rng([int(seed), i, 0x5EED])
        d = nominal()
        for k, spec in SPREAD.items():
            base = d[k]
            if spec[0] == "lognormal":
                d[k] = float(base * math.exp(spec[1] * rng.standard_normal()))
            elif spec[0] == "uniform":
                d[k] = float(rng.uniform(spec[1], spec[2]))
            else:
                d[k] = float(base * max(0.5, 1.0 + spec[1] * rng.standard_normal()))
        d["effect_scale"] = {k: float(max(0.3, 1.0 + s * rng.standard_normal())) for k, s in EFFECT_SPREAD.items()}
        # one stiffness factor for the whole torsion curve (keeps K1 <= K2 <= K3)
        for k in ("nonlinear_stiffness.K2", "nonlinear_stiffness.K3"):
            d["effect_scale"][k] = d["effect_scale"]["nonlinear_stiffness.K1"]
        for ph in PHASES:
            d[ph] = float(rng.uniform(0.0, 2.0 * math.pi))
        d["actuator_id"] = f"{id_prefix}-{i:04d}"
        d["seed"] = int(seed)
        out.append(d)
    return out


def gear_ratio(p: Mapping[str, Any]) -> float:
    """N = Z_CS / (Z_CS - Z_FS) for FS fixed, CS output (same direction)."""
    dz = p["Z_CS"] - p["Z_FS"]
    if dz <= 0:
        raise ValueError(f"Z_CS ({p['Z_CS']}) must exceed Z_FS ({p['Z_FS']})")
    return float(p["Z_CS"] / dz)


def check_params(p: Mapping[str, Any]) -> None:
    """Refuse absurd values with a clear message (name, value, allowed range)."""
    ranges = {
        "r_m": (0.005, 0.5), "r_b": (0.005, 0.5), "J_WG_plug": (1e-7, 1.0), "J_rotor": (0.0, 1.0),
        "J_CS": (1e-5, 10.0), "J_L": (0.0, 1e3), "m_FSx": (1e-4, 100.0), "m_FSy": (1e-3, 100.0),
        "K_aero": (0.0, 1e6), "k_t": (0.01, 20.0), "R0": (1e-3, 100.0), "L": (1e-6, 1.0),
        "V_dc": (5.0, 2000.0), "i_max": (0.1, 2000.0), "k_D": (0.0, 1e-10), "mission_hours": (0.0, 1e5),
        "h_fail": (1e-7, 1e-3), "delta_0": (0.0, 1e-4), "split_mesh": (0.05, 0.9), "split_FS": (0.05, 0.9),
        "f_w": (1.0, 1000.0), "f_p": (0.1, 100.0), "f_i": (50.0, 1e4), "C_w": (1.0, 1e6), "C_h": (1.0, 1e7),
    }
    for k, (lo, hi) in ranges.items():
        v = p.get(k)
        if v is None:
            raise KeyError(f"actuator parameter {k!r} missing")
        if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"actuator parameter {k} = {v!r} outside the physical range [{lo:g}, {hi:g}]")
    if p["split_mesh"] + p["split_FS"] >= 0.95:
        raise ValueError("split_mesh + split_FS must leave >= 5 % of the compliance to the WG bearing")


def new_health() -> dict[str, float]:
    """Health state of a new unit: no wear, no flexspline or lubrication fault."""
    return {"h_plus": 0.0, "h_minus": 0.0, "fs_loss": 0.0, "lube_loss": 0.0}


def archard_increment(W: float, p: Mapping[str, Any], duration: float, lube_loss: float = 0.0) -> float:
    """Accelerated wear depth [m] on one flank from the mission integral W = int |T_out||omega_m| dt [J].

    The mission of ``duration`` s stands for ``mission_hours`` of operation with the same load
    spectrum, so the acceleration factor is mission_hours * 3600 / duration.

    PHYSICS.md 4: h' = 2 f_WG k_D T/(r_m n_eff cos(alpha) b) with f_WG = |omega_m|/(2 pi), i.e.
    dh = k_D W / (pi r_m n_eff cos(alpha) b); times the acceleration factor, and x (1 + 4 s) under
    lubrication loss of severity s.

    The sliding distance per tooth engagement scales with the tooth size (module 2 r_m / Z_FS), so
    the increment carries ``module_factor(p)`` (1 for the nominal 200-tooth size-65 gear): at another
    gear ratio (more, smaller teeth, more WG revolutions per output radian) the wear per output
    motion at the same output torque stays the same.
    """
    denom = math.pi * p["r_m"] * p["n_eff"] * math.cos(p["alpha_p"]) * p["b_face"]
    if duration <= 0:
        raise ValueError(f"archard_increment: duration {duration} s <= 0")
    accel = p["mission_hours"] * 3600.0 / duration
    return float(accel * p["k_D"] * (1.0 + 4.0 * lube_loss) * W / denom * module_factor(p))


def module_factor(p: Mapping[str, Any]) -> float:
    """Tooth module relative to the nominal gear's (2 r_m / Z_FS over 2 * 0.0825 / 200)."""
    f = (p["r_m"] / p["Z_FS"]) / (NOMINAL["r_m"][0] / NOMINAL["Z_FS"][0])
    return 1.0 if abs(f - 1.0) < 1e-12 else f


def teeth_for_ratio(N: int) -> tuple[int, int]:
    """(Z_FS, Z_CS) of a cup-type gear with flexspline fixed, circular spline output: N = Z_CS/(Z_CS - Z_FS)."""
    N = int(N)
    if N < 30 or N > 320:
        raise ValueError(f"gear ratio {N} outside the strain-wave range 30-320")
    return 2 * N - 2, 2 * N
