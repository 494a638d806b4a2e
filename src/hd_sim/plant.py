"""One mission of one actuator: parameters + effects + health + profile -> (Mission, ground truth).

Pure python/numpy around the compiled time loop of :mod:`hd_sim.kernel`.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from hd_bag.mission import Mission, MissionMeta, TEMPERATURE_FRAMES

from . import kernel as K
from .effects import EffectSet
from .params import check_params, gear_ratio, new_health, nominal
from .profiles import Profile, make_profile

ARCMIN = math.pi / (180.0 * 60.0)

#: /sim/internal quantity names written to bags (all logged kernel columns).
INTERNAL_NAMES = K.OUT_NAMES


def _eff(params: Mapping[str, Any], effects: EffectSet, name: str, key: str) -> float:
    """Effect parameter with the unit's spread factor, unless the user overrode it."""
    v = effects.p(name, key)
    if (name, key) not in effects.overridden:
        v *= params.get("effect_scale", {}).get(f"{name}.{key}", 1.0)
    return v


def wear_backlash(params: Mapping[str, Any], h_plus: float, h_minus: float) -> float:
    """The mesh's backlash gap from flank wear [m, along the line of action's tangent]: ``max(0, h+ + h- -
    2 delta_0) / cos(alpha_p)`` (PHYSICS.md 4: it opens once the flexspline's interference preload delta_0 is worn
    through); divided by r_m it is the lost motion at the output [rad]."""
    return max(0.0, h_plus + h_minus - 2.0 * float(params["delta_0"])) / math.cos(float(params["alpha_p"]))


def bouc_wen_width(z_max: float, A: float, k_FS: float, F_pk: float) -> float:
    """Zero-force loop width [m of y_FS] of k_FS y + z (Bouc-Wen n = 1, beta = gamma) cycled to +-F_pk.

    Unloading from the saturated branch: z falls linearly (slope A) to 0, then
    approaches -z_max exponentially; closed form plus a scalar root.
    """
    from scipy.optimize import brentq

    y_pk = (F_pk - z_max) / k_FS
    d1 = z_max / A
    D = (k_FS * y_pk + z_max) / (k_FS + A)
    if D > d1:
        f = lambda D_: k_FS * (y_pk - D_) - z_max * (1.0 - math.exp(-A * (D_ - d1) / z_max))  # noqa: E731
        D = brentq(f, d1, abs(y_pk) + 20.0 * z_max / min(k_FS, A) + d1)
    return 2.0 * abs(y_pk - D)


def bouc_wen_z_max(width: float, A: float, k_FS: float, F_pk: float) -> float:
    """z_max [N] giving the zero-force loop ``width`` [m] at +-F_pk.

    If A is too small to reach ``width`` (the loop width peaks as z_max grows), the
    widest reachable loop is used when the shortfall is < 15 %; else ValueError.
    """
    zs = np.linspace(F_pk * 1e-3, 0.9 * F_pk, 200)
    w = np.array([bouc_wen_width(z, A, k_FS, F_pk) for z in zs])
    i_pk = int(np.argmax(w))
    if width > w[i_pk]:
        if width <= 1.15 * w[i_pk]:
            return float(zs[i_pk])
        raise ValueError(f"hysteresis loss of {width:.3g} m unreachable with Bouc-Wen A = {A:.3g} N/m (max "
                         f"{w[i_pk]:.3g} m): raise hysteresis.A_ratio (and --n-sub for stability)")
    return float(np.interp(width, w[: i_pk + 1], zs[: i_pk + 1]))


def bouc_wen_params(params: Mapping[str, Any], effects: EffectSet, k_FS: float) -> tuple[float, float, float]:
    """(bw_A [N/m], z_max [N], bw_beta = bw_gamma [1/m]) of the flexspline hysteresis for stiffness k_FS [N/m].

    The zero-torque loop width at +-T_rated equals ``hysteresis.loss_arcmin`` at the output, whatever k_FS.
    """
    bw_A = effects.p("hysteresis", "A_ratio") * k_FS
    loss = effects.p("hysteresis", "loss_arcmin") * ARCMIN * params["r_m"]
    on = effects.is_on("hysteresis") and loss > 0
    z_max = bouc_wen_z_max(loss, bw_A, k_FS, params["T_rated"] / params["r_m"]) if on else 0.0
    return bw_A, z_max, (bw_A / (2.0 * z_max) if z_max > 0 else 0.0)


def derived(params: Mapping[str, Any], effects: EffectSet, health: Mapping[str, float]) -> dict[str, float]:
    """Physical parameters of this mission (after wear and faults), SI; written to /sim/effects 'params'."""
    check_params(params)
    p = params
    N = gear_ratio(p)
    r_m, r_b = p["r_m"], p["r_b"]
    mu_g = r_m / (N * r_b)
    on = effects.is_on
    K1 = _eff(p, effects, "nonlinear_stiffness", "K1")
    K2 = _eff(p, effects, "nonlinear_stiffness", "K2")
    K3 = _eff(p, effects, "nonlinear_stiffness", "K3")
    T1 = effects.p("nonlinear_stiffness", "T1")
    T2 = effects.p("nonlinear_stiffness", "T2")
    if not (0 < K1 <= K2 <= K3 and 0 < T1 < T2):
        raise ValueError(f"nonlinear_stiffness needs 0 < K1 <= K2 <= K3 and 0 < T1 < T2 (got K={K1:g},{K2:g},{K3:g}, "
                         f"T={T1:g},{T2:g})")
    C3 = 1.0 / K3
    s_mesh, s_fs = p["split_mesh"], p["split_FS"]
    s_b = 1.0 - s_mesh - s_fs
    k_FS = 1.0 / (s_fs * C3 * r_m**2)
    k_b = mu_g**2 / (s_b * C3 * r_m**2)
    c_rest = (1.0 - s_mesh) * C3
    if 1.0 / K1 <= c_rest:
        raise ValueError(f"K1 = {K1:g} too stiff for the compliance split (needs K1 < K3/(1 - split_mesh))")
    k_m = [1.0 / (r_m**2 * (1.0 / Ki - c_rest)) for Ki in (K1, K2, K3)]
    u1 = (T1 / r_m) / k_m[0]
    u2 = u1 + ((T2 - T1) / r_m) / k_m[1]
    # ---- law slots (effects.LAW_SLOTS): one choice each ---------------------------------------
    fric_choice = effects.law("friction_transition")
    tors_choice = effects.law("torsion")
    k_cub = 0.0
    if tors_choice == "cubic":
        K1c = effects.p("cubic_stiffness", "K1")
        K3c = effects.p("cubic_stiffness", "K3c")
        if not (K1c > 0 and 1.0 / K1c > c_rest and K3c >= 0):
            raise ValueError(f"cubic_stiffness needs K1 > 0 below K3/(1 - split_mesh) and K3c >= 0 "
                             f"(got K1={K1c:g}, K3c={K3c:g})")
        k_m[0] = 1.0 / (r_m**2 * (1.0 / K1c - c_rest))  # mesh linear slope (kernel k_m1 under the cubic law)
        k_cub = K3c / r_m**4  # F = k_cub u^3 [N, m] <=> T = K3c (u/r_m)^3 [N*m, rad]
    hp, hm = float(health.get("h_plus", 0.0)), float(health.get("h_minus", 0.0))
    for nm, v in (("h_plus", hp), ("h_minus", hm)):
        if not (math.isfinite(v) and 0.0 <= v < 5e-4):
            raise ValueError(f"health {nm} = {v!r} m outside [0, 0.5 mm)")
    h = 0.5 * (hp + hm)
    wear = on("meshing_wear")
    hw = h if wear else 0.0
    h_fail = p["h_fail"]
    module = 2.0 * r_m / p["Z_FS"]
    t0 = math.pi * module / 2.0
    km_scale = (1.0 - hw / t0) ** 3 / (1.0 + effects.p("meshing_wear", "kappa_n") * hw / h_fail)
    fs_loss = float(health.get("fs_loss", 0.0)) if on("flexspline_stiffness_loss") else 0.0
    if on("flexspline_stiffness_loss"):
        fs_loss = max(fs_loss, effects.p("flexspline_stiffness_loss", "loss"))
    lube = float(health.get("lube_loss", 0.0)) if on("lubrication_loss") else 0.0
    if on("lubrication_loss"):
        lube = max(lube, effects.p("lubrication_loss", "severity"))
    if not (0.0 <= fs_loss < 0.95 and 0.0 <= lube <= 10.0):
        raise ValueError(f"fault severities out of range: flexspline loss {fs_loss}, lubrication {lube}")
    k_FS_eff = k_FS * (1.0 - fs_loss)
    j = 0.0
    if on("backlash"):
        j = wear_backlash(p, hp, hm) if wear else 0.0
        j += effects.p("backlash", "j0")
    w_bl = max(effects.p("backlash", "smooth") * j, 1e-9)
    if tors_choice == "deadzone":
        wdz = effects.p("deadzone_stiffness", "width_arcmin") * ARCMIN * r_m
        if not (wdz >= 0 and effects.p("deadzone_stiffness", "smooth") > 0):
            raise ValueError("deadzone_stiffness needs width_arcmin >= 0 and smooth > 0")
        w_bl = max(effects.p("deadzone_stiffness", "smooth") * (j + wdz), 1e-9)
    else:
        wdz = 0.0
    # hysteresis: zero-torque loop width (output angle) at +-T_rated = loss_arcmin
    bw_A, z_max, bw_beta = bouc_wen_params(p, effects, k_FS_eff)
    bw_gamma = bw_beta
    mu_c = 0.0
    if on("load_dependent_friction"):
        mu_c = (_eff(p, effects, "load_dependent_friction", "mu_flank") * mu_g
                * (1.0 + effects.p("meshing_wear", "kappa_mu") * hw / h_fail) * (1.0 + lube))
    A2 = A1 = A4 = B1 = B2 = 0.0
    if on("kinematic_error_harmonic"):
        kke = effects.p("meshing_wear", "kappa_KE")
        A2 = _eff(p, effects, "kinematic_error_harmonic", "A2") + kke * hw
        A1 = effects.p("kinematic_error_harmonic", "A1_ratio") * A2
        A4 = effects.p("kinematic_error_harmonic", "A4_ratio") * A2
        B1 = effects.p("kinematic_error_harmonic", "B1")
        B2 = effects.p("kinematic_error_harmonic", "B2")
        order = int(round(effects.p("kinematic_error_harmonic", "order")))
        if order:
            if order not in (1, 2, 4):
                raise ValueError(f"kinematic_error_harmonic.order = {order}: must be 1, 2 or 4")
            A1, A2, A4 = ((A1 or 0.3 * A2) if order == 1 else 0.0, A2 if order == 2 else 0.0,
                          (A4 or 0.2 * A2) if order == 4 else 0.0)
            B1 = B2 = 0.0
    wear_fric = (1.0 + effects.p("meshing_wear", "kappa_TC") * hw / h_fail) * (1.0 + lube)
    T_C = _eff(p, effects, "coulomb_friction", "T_C") * wear_fric if on("coulomb_friction") else 0.0
    T_C_out = effects.p("coulomb_friction", "T_C_out") * (1.0 + lube) if on("coulomb_friction") else 0.0
    b_in = _eff(p, effects, "viscous_friction", "b") * (1.0 + lube) if on("viscous_friction") else 0.0
    b_out = effects.p("viscous_friction", "b_out") * (1.0 + lube) if on("viscous_friction") else 0.0
    F = [0.0, 0.0, 0.0, 0.0]
    if on("position_periodic_friction"):
        F = [_eff(p, effects, "position_periodic_friction", f"F{k}") for k in (1, 2, 3, 4)]
        order = int(round(effects.p("position_periodic_friction", "order")))
        if order:
            if order not in (1, 2, 3, 4):
                raise ValueError(f"position_periodic_friction.order = {order}: must be 1..4")
            F = [(F[k - 1] or 0.1) if k == order else 0.0 for k in (1, 2, 3, 4)]
    J_WG = p["J_WG_plug"] + p["J_rotor"]
    psi_m = p["k_t"] / (1.5 * p["p"])
    d = dict(
        N=N, r_m=r_m, r_b=r_b, mu_g=mu_g, J_WG=J_WG, J_CS=p["J_CS"], J_L=p["J_L"],
        m_FSx=p["m_FSx"], m_FSy=p["m_FSy"],
        k_b=k_b, c_b=p["c_b"], k_FS=k_FS_eff, c_FS=p["c_FS"], c_m=p["c_m"],
        k_m1=k_m[0], k_m2=k_m[1], k_m3=k_m[2], u1=u1, u2=u2, km_scale=km_scale,
        nl_on=float(on("nonlinear_stiffness")),
        eps_s=effects.p("position_dependent_stiffness", "eps") if on("position_dependent_stiffness") else 0.0,
        psi_s=p.get("psi_s", 0.0), j_bl=j + wdz, w_bl=w_bl,
        bw_A=bw_A, bw_beta=bw_beta, bw_gamma=bw_gamma, hyst_on=float(on("hysteresis") and z_max > 0),
        bw_exact=float(effects.p("hysteresis", "exact_step") > 0.5),
        mu_c=mu_c, A1=A1, A2=A2, A4=A4, psi1=p.get("psi1", 0.0), psi2=p.get("psi2", 0.0),
        psi4=p.get("psi4", 0.0), a_T=effects.p("kinematic_error_harmonic", "a_T"), T_rated=p["T_rated"],
        B1=B1, B2=B2, chi1=p.get("chi1", 0.0), chi2=p.get("chi2", 0.0),
        T_C=T_C, T_S_ratio=effects.p("stribeck_friction", "ratio"),
        omega_s=effects.p("stribeck_friction", "omega_s"), delta_s=effects.p("stribeck_friction", "delta"),
        stribeck_on=float(on("stribeck_friction") and T_C > 0), b_in=b_in,
        F1=F[0], F2=F[1], F3=F[2], F4=F[3], rho1=p.get("rho1", 0.0), rho2=p.get("rho2", 0.0),
        rho3=p.get("rho3", 0.0), rho4=p.get("rho4", 0.0),
        nu_beta=effects.p("temperature_dependent_friction", "beta"),
        T_ref=effects.p("temperature_dependent_friction", "T_ref"),
        n_b=effects.p("temperature_dependent_friction", "n_b"), n_c=effects.p("temperature_dependent_friction", "n_c"),
        tdf_on=float(on("temperature_dependent_friction")),
        eps_v=(effects.p("smooth_friction", "width") if fric_choice == "tanh" else
               effects.p("lugre_friction", "eps_v") if fric_choice == "lugre" else effects.p("coulomb_friction", "eps_v")),
        fric_law=1.0 if fric_choice == "lugre" else 0.0,
        lg_sigma0=effects.p("lugre_friction", "sigma0") if fric_choice == "lugre" else 0.0,
        lg_sigma1=effects.p("lugre_friction", "sigma1") if fric_choice == "lugre" else 0.0,
        tors_law=1.0 if tors_choice == "cubic" else 0.0, k_cub=k_cub,
        mu_bb=effects.p("bearing_load_friction", "mu_bb") * (1.0 + lube) if on("bearing_load_friction") else 0.0,
        P1=effects.p("position_periodic_torque", "P1") if on("position_periodic_torque") else 0.0,
        P2=effects.p("position_periodic_torque", "P2") if on("position_periodic_torque") else 0.0,
        phi_p1=p.get("phi_p1", 0.0), phi_p2=p.get("phi_p2", 0.0),
        C1=_eff(p, effects, "cogging_torque", "C1") if on("cogging_torque") else 0.0,
        C2=effects.p("cogging_torque", "C2") if on("cogging_torque") else 0.0,
        N_c=effects.p("cogging_torque", "N_c"), phi_c1=p.get("phi_c1", 0.0), phi_c2=p.get("phi_c2", 0.0),
        r6=effects.p("current_ripple", "r6") if on("current_ripple") else 0.0,
        r12=effects.p("current_ripple", "r12") if on("current_ripple") else 0.0,
        phi_r6=p.get("phi_r6", 0.0), phi_r12=p.get("phi_r12", 0.0),
        T_C_out=T_C_out, b_out=b_out, K_aero=p["K_aero"], c_aero=p["c_aero"],
        p=float(p["p"]), R0=p["R0"], L=p["L"], psi_m=psi_m,
        alpha_R=effects.p("motor_thermal_drift", "alpha_R"), alpha_psi=effects.p("motor_thermal_drift", "alpha_psi"),
        drift_on=float(on("motor_thermal_drift")), V_max=p["V_dc"] / math.sqrt(3.0), i_max=p["i_max"],
        psi_hat=psi_m, R_hat=p["R0"],
        C_w=p["C_w"], R_wh=p["R_wh"], C_h=p["C_h"], R_ha=p["R_ha"], heat_on=float(on("self_heating")),
        # reporting only
        k_t=p["k_t"], h=h, h_plus=hp, h_minus=hm, h_fail=h_fail, backlash_j=j, fs_loss=fs_loss, lube_loss=lube,
        k_m_eff=k_m[2] * km_scale, k_D=p["k_D"], z_max=z_max, t0=t0,
        K1=K1, K2=K2, K3=K3, T1=T1, T2=T2, friction_law=fric_choice, torsion_law=tors_choice,
        K_out_lin=1.0 / (1.0 / (k_m[2] * km_scale * r_m**2) + 1.0 / (k_FS_eff * r_m**2) + mu_g**2 / (k_b * r_m**2)),
    )
    return d


def kernel_vector(d: Mapping[str, float], p: Mapping[str, Any], fs: float, n_sub: int, quant_f: float,
                  input_locked: bool, K_aero_scale: float = 1.0) -> np.ndarray:
    """Pack the kernel parameter vector (layout ``kernel.KNAMES``) incl. controller gains."""
    dt = 1.0 / (fs * n_sub)
    w_i, w_w, w_p = (2 * math.pi * p[k] for k in ("f_i", "f_w", "f_p"))
    J_tot = d["J_WG"] + (d["J_CS"] + d["J_L"]) / d["N"] ** 2
    kt = 1.5 * d["p"] * d["psi_m"]
    ctrl = dict(
        Kp_i=d["L"] * w_i, Ki_i=d["R0"] * w_i, Kp_w=J_tot * w_w / kt, Ki_w=J_tot * w_w / kt * w_w / 4.0,
        Kp_p=w_p, omega_max_f=math.radians(p["rate_max_deg"]),
        n_ctrl=float(max(1, int(round(1.0 / (p["f_ctrl"] * dt))))), q_f=quant_f,
        input_locked=float(input_locked), dt=dt, n_sub=float(n_sub),
        flt_n_on=-1.0, flt_n_ramp=1.0, flt_fric=1.0, flt_kFS=1.0, flt_bwA=1.0, flt_bwb=1.0,  # no fault
    )
    if not (d["eps_v"] > 0 and d["lg_sigma0"] >= 0 and d["lg_sigma1"] >= 0):
        raise ValueError(f"friction law: need eps_v/width > 0 and LuGre sigma0, sigma1 >= 0 (got eps_v "
                         f"{d['eps_v']:g}, sigma0 {d['lg_sigma0']:g}, sigma1 {d['lg_sigma1']:g})")
    if d["fric_law"] > 0.5 and not d["lg_sigma0"] > 0:
        raise ValueError("lugre_friction.sigma0 must be > 0")
    v = np.empty(len(K.KNAMES))
    for name, i in K.KI.items():
        v[i] = ctrl[name] if name in ctrl else d[name]
    v[K.KI["K_aero"]] *= K_aero_scale
    v[K.KI["c_aero"]] *= K_aero_scale
    if not np.all(np.isfinite(v)):
        bad = [n for n, i in K.KI.items() if not np.isfinite(v[i])]
        raise ValueError(f"non-finite plant parameters: {bad}")
    return v


#: Faults that can start inside a mission -> the severity's meaning and its admissible range.
MID_MISSION_FAULTS = {
    "lubrication_loss": ("severity: friction x (1 + severity) (T_C, T_C_out, b, b_out, mu_c, mu_bb)", 0.0, 10.0),
    "flexspline_stiffness_loss": ("severity: fraction of k_FS lost, k_FS x (1 - severity)", 0.0, 0.95),
}
#: Default ramp of a mid-mission fault [s]: a short, not instantaneous, onset (grease squeezed out,
#: a crack through the flexspline wall); 0 gives a step at the next internal step.
FAULT_RAMP_S = 0.05


def parse_fault(text: str) -> dict[str, Any]:
    """``NAME:SEVERITY@T_ONSET[/T_RAMP]`` (s) -> fault dict for :func:`simulate_mission`."""
    try:
        name, rest = text.split(":", 1)
        sev, rest = rest.split("@", 1)
        t_on, _, ramp = rest.partition("/")
        f = {"name": name.strip(), "severity": float(sev), "t_onset": float(t_on)}
        if ramp:
            f["t_ramp"] = float(ramp)
    except ValueError:
        raise ValueError(f"fault {text!r}: expected NAME:SEVERITY@T_ONSET[/T_RAMP], e.g. "
                         f"lubrication_loss:3@10 or flexspline_stiffness_loss:0.3@8/0.1") from None
    if f["name"] not in MID_MISSION_FAULTS:
        raise ValueError(f"fault {text!r}: name {f['name']!r} is not one of {sorted(MID_MISSION_FAULTS)}")
    return f


def fault_vector(fault: Mapping[str, Any], d: Mapping[str, float], duration: float, dt: float,
                 params: Mapping[str, Any], effects: EffectSet) -> tuple[dict[str, float], dict[str, Any]]:
    """Kernel entries ``flt_*`` and the /sim/effects record of a mid-mission fault.

    fault: ``{"name", "severity", "t_onset" [s from the first sample], "t_ramp" [s, default
    FAULT_RAMP_S]}``; d: :func:`derived` of the mission (its ``lube_loss``/``fs_loss`` are the
    state before the onset: the fault takes them to ``max(before, severity)``, per the effect's
    law in :func:`derived`, and never heals). A flexspline loss also moves the Bouc-Wen
    parameters to the values :func:`derived` gives at the new k_FS (:func:`bouc_wen_params`: the
    same hysteresis loss in arcmin), so after the ramp the plant equals a mission started with the
    fault. Raises ValueError naming the bad field.
    """
    if not isinstance(fault, Mapping):
        raise ValueError(f"fault must be a dict {{name, severity, t_onset[, t_ramp]}}, got {type(fault).__name__}")
    unknown = set(fault) - {"name", "severity", "t_onset", "t_ramp"}
    if unknown:
        raise ValueError(f"fault: unknown keys {sorted(unknown)}")
    name = fault.get("name")
    if name not in MID_MISSION_FAULTS:
        raise ValueError(f"fault name {name!r}: mid-mission faults are {sorted(MID_MISSION_FAULTS)}")
    _, lo, hi = MID_MISSION_FAULTS[name]
    try:
        sev = float(fault["severity"]); t_on = float(fault["t_onset"])
        ramp = float(fault.get("t_ramp", FAULT_RAMP_S))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"fault {name}: severity, t_onset (and t_ramp) must be numbers ({e!r})") from None
    if not (math.isfinite(sev) and lo <= sev <= hi):
        raise ValueError(f"fault {name}: severity {sev!r} outside [{lo}, {hi}]")
    if not (math.isfinite(t_on) and 0.0 <= t_on < duration):
        raise ValueError(f"fault {name}: t_onset {t_on!r} s outside the mission [0, {duration:g}) s")
    if not (math.isfinite(ramp) and ramp >= 0.0):
        raise ValueError(f"fault {name}: t_ramp {ramp!r} s must be finite and >= 0")
    fric = kfs = bwA = bwb = 1.0
    z_after = float(d["z_max"])
    if name == "lubrication_loss":
        before = float(d["lube_loss"]); after = max(before, sev)
        fric = (1.0 + after) / (1.0 + before)
    else:
        before = float(d["fs_loss"]); after = max(before, sev)
        kfs = (1.0 - after) / (1.0 - before)
        if d["z_max"] > 0:
            A1, z_after, b1 = bouc_wen_params(params, effects, d["k_FS"] * kfs)
            bwA, bwb = A1 / d["bw_A"], b1 / d["bw_beta"]
    n_on = float(round(t_on / dt))
    n_ramp = float(max(1, int(round(ramp / dt))))
    kv = {"flt_n_on": n_on, "flt_n_ramp": n_ramp, "flt_fric": fric, "flt_kFS": kfs, "flt_bwA": bwA, "flt_bwb": bwb}
    rec = {"name": name, "severity": sev, "t_onset": n_on * dt, "t_ramp": n_ramp * dt,
           "before": before, "after": after, "friction_factor": fric, "k_FS_factor": kfs,
           "bw_A_factor": bwA, "bw_beta_factor": bwb, "z_max_after": z_after,
           "law": MID_MISSION_FAULTS[name][0]}
    return kv, rec


def _mesh_inverse(F: float, P: np.ndarray) -> float:
    """Mesh deflection ug (after the dead zone) that carries the elastic force F (km_scale included)."""
    g = K.KI
    ks = P[g["km_scale"]]
    k1, k2, k3, u1, u2 = (P[g[n]] for n in ("k_m1", "k_m2", "k_m3", "u1", "u2"))
    f = abs(F) / ks
    if P[g["tors_law"]] > 0.5:  # cubic: k1 a + k_cub a^3 = f (monotone: Newton from the linear guess)
        k1, kc = P[g["k_m1"]], P[g["k_cub"]]
        a = f / k1
        for _ in range(60):
            a -= (k1 * a + kc * a**3 - f) / (k1 + 3.0 * kc * a * a)
    elif P[g["nl_on"]] < 0.5:
        a = f / k3
    elif f <= k1 * u1:
        a = f / k1
    elif f <= k1 * u1 + k2 * (u2 - u1):
        a = u1 + (f - k1 * u1) / k2
    else:
        a = u2 + (f - k1 * u1 - k2 * (u2 - u1)) / k3
    return math.copysign(a, F)


def initial_state(P: np.ndarray, theta_f0: float, T_load0: float, T_w0: float, T_h0: float,
                  kt: float) -> np.ndarray:
    """Static equilibrium at rest holding ``T_load0`` at ``theta_f0`` (no hysteresis offset)."""
    g = K.KI
    r_m, r_b, mu_g = P[g["r_m"]], P[g["r_b"]], P[g["mu_g"]]
    F = T_load0 / r_m
    ug = _mesh_inverse(F, P)
    j = P[g["j_bl"]]
    u = ug + (math.copysign(0.5 * j, F) if F != 0.0 and j > 0 else 0.0)
    y = -F / P[g["k_FS"]]
    d_b = mu_g * F / P[g["k_b"]]
    th_m = P[g["N"]] * theta_f0
    for _ in range(4):  # e_KE depends on theta_m
        sm = np.sin
        th_ke = (P[g["A1"]] * sm(th_m + P[g["psi1"]]) + P[g["A2"]] * sm(2 * th_m + P[g["psi2"]])
                 + P[g["A4"]] * sm(4 * th_m + P[g["psi4"]]) + P[g["B1"]] * sm(theta_f0 + P[g["chi1"]])
                 + P[g["B2"]] * sm(2 * theta_f0 + P[g["chi2"]]))
        d_m = u - r_m * th_ke
        x = (d_m - y + r_m * theta_f0) / mu_g
        th_m = (x + d_b) / r_b
    x0 = np.zeros(len(K.SNAMES))
    s = K.SI
    x0[s["theta_m"]] = th_m
    x0[s["x_FS"]] = x
    x0[s["y_FS"]] = y
    x0[s["theta_f"]] = theta_f0
    i_q = (P[g["k_b"]] * d_b) * r_b / kt
    x0[s["i_q"]] = i_q
    x0[s["I_w"]] = i_q
    x0[s["I_q"]] = P[g["R0"]] * i_q
    x0[s["T_w"]] = T_w0
    x0[s["T_h"]] = T_h0
    return x0


#: Internal step the plant is integrated with at any log rate (40 sub-steps at 1 kHz).
DT_INTERNAL = 25e-6


def default_n_sub(fs: float) -> int:
    """Internal steps per log sample keeping dt = 25 us (the stiff internal modes need it): 40 at 1 kHz."""
    return max(1, int(round(1.0 / (float(fs) * DT_INTERNAL))))


def first_order_lowpass(x: np.ndarray, f_c: float, fs: float) -> np.ndarray:
    """y' = 2 pi f_c (x - y) sampled at fs (exact for x held over each period), y[0] = x[0]."""
    from scipy.signal import lfilter

    if not (f_c > 0 and math.isfinite(f_c)):
        raise ValueError(f"filter bandwidth f_c = {f_c!r} Hz must be > 0")
    a = 1.0 - math.exp(-2.0 * math.pi * f_c / fs)
    y, _ = lfilter([a], [1.0, a - 1.0], x, zi=[(1.0 - a) * x[0]])
    return y


def drive_speed(theta_q: np.ndarray, f_c: float, fs: float) -> np.ndarray:
    """A drive's speed estimate: backward difference of the quantised angle, low-passed at f_c (lagged)."""
    d = np.empty_like(theta_q)
    d[1:] = np.diff(theta_q) * fs
    d[0] = 0.0
    return first_order_lowpass(d, f_c, fs)


def _quantise(x: np.ndarray, q: float) -> np.ndarray:
    return q * np.floor(x / q + 0.5) if q > 0 else x


def simulate_mission(params: Mapping[str, Any] | None = None, effects: EffectSet | None = None,
                     profile: str | Profile = "inspection", seed: int = 0, *, duration: float = 20.0,
                     fs: float = 1000.0, health: Mapping[str, float] | None = None, mission_index: int = 0,
                     operating_hours: float = 0.0, n_sub: int | None = None, T_amb: float | None = None,
                     input_locked: bool = False, T_ext: np.ndarray | None = None,
                     fault: Mapping[str, Any] | None = None,
                     ) -> tuple[Mission, dict[str, Any]]:
    """Simulate one mission; returns the contract :class:`Mission` and the ground truth.

    params: actuator (``nominal()`` or one of ``sample_population``); effects:
    :class:`EffectSet` (default: realistic ``EffectSet.default()``); profile:
    a kind from ``hd_sim.profiles.PROFILES`` or a :class:`Profile`; seed drives
    the profile, gusts and sensor noise; health: ``{h_plus, h_minus, fs_loss,
    lube_loss}`` at the mission start (default new); n_sub: internal steps per
    log sample (dt = 1/(fs n_sub); default ``default_n_sub(fs)``: dt = 25 us at any log
    rate, 40 at 1 kHz); input_locked: WG held (static torsion
    tests); T_ext: optional extra hinge moment per log sample [N*m]; fault: a
    fault starting inside the mission, ``{"name": "lubrication_loss" |
    "flexspline_stiffness_loss", "severity": x, "t_onset": s[, "t_ramp": s]}``
    (see :func:`fault_vector`; applied in the kernel, recorded in
    ``/sim/effects["fault"]`` and per sample as ``fault_active``/``fault_phi``
    in ``/sim/internal``). Before the onset the mission is bit-identical to the
    one without fault (same seed).

    Ground truth: ``{"internal": {name: array on the full time grid, "t": t},
    "health": {...}, "effects": {"effects": ..., "params": ...}, "wear":
    {"W_plus", "W_minus"} (J, int max(+-T_tr, 0) |omega_m| dt)}``.
    """
    params = dict(params) if params is not None else nominal()
    effects = effects if effects is not None else EffectSet.default()
    health = dict(new_health(), **(health or {}))
    if not isinstance(profile, str):
        fs = profile.fs
    if n_sub is None:
        n_sub = default_n_sub(fs)
    if not (1 <= int(n_sub) <= 1000):
        raise ValueError(f"n_sub = {n_sub} outside [1, 1000]")
    if isinstance(profile, str):
        profile = make_profile(profile, duration, fs, seed, rate_max_deg=params["rate_max_deg"], T_amb=T_amb)
    else:
        fs = profile.fs
    n = profile.n
    if n < 2:
        raise ValueError(f"mission of {n} samples is too short")
    d = derived(params, effects, health)
    q_m = 2 * math.pi / 2 ** effects.p("encoder_quantisation", "bits_m") if effects.is_on("encoder_quantisation") else 0.0
    q_f = 2 * math.pi / 2 ** effects.p("encoder_quantisation", "bits_f") if effects.is_on("encoder_quantisation") else 0.0
    P = kernel_vector(d, params, fs, int(n_sub), q_f, input_locked, profile.q_scale)
    fault_rec = None
    if fault is not None:
        kv, fault_rec = fault_vector(fault, d, n / fs, float(P[K.KI["dt"]]), params, effects)
        for k, v in kv.items():
            P[K.KI[k]] = v
    rng_env = np.random.default_rng([int(seed), 0xA7B])
    gust = profile.gust * (effects.p("aero_gusts", "sigma") if effects.is_on("aero_gusts") else 0.0)
    if T_ext is not None:
        T_ext = np.asarray(T_ext, dtype=np.float64)
        if T_ext.shape != (n,) or not np.all(np.isfinite(T_ext)):
            raise ValueError(f"T_ext must be {n} finite values (got shape {T_ext.shape})")
        gust = gust + T_ext
    T_amb_ = profile.T_amb
    T_h0 = profile.T_h0 if profile.T_h0 is not None else T_amb_ + float(rng_env.uniform(0.0, 15.0))
    T_w0 = profile.T_w0 if profile.T_w0 is not None else T_h0 + float(rng_env.uniform(0.0, 5.0))
    th0 = float(profile.theta_ref[0])
    T_load0 = P[K.KI["K_aero"]] * th0 + gust[0]
    x0 = initial_state(P, th0, T_load0, T_w0, T_h0, 1.5 * d["p"] * d["psi_m"])
    out = np.empty((n, len(K.OUT_NAMES)))
    xf = K.integrate(P, x0, np.ascontiguousarray(profile.theta_ref, dtype=np.float64),
                     np.ascontiguousarray(profile.omega_ff, dtype=np.float64),
                     np.ascontiguousarray(gust, dtype=np.float64), float(T_amb_), out)
    if not np.all(np.isfinite(out)):
        bad = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise FloatingPointError(f"plant diverged at sample {bad} (t = {bad / fs:.3f} s); parameters: "
                                 f"check stiffness/inertia values and n_sub (dt = {P[K.KI['dt']]:.2e} s)")
    t = np.arange(n) / fs
    col = {name: out[:, i] for i, name in enumerate(K.OUT_NAMES)}

    # ---- sensors ------------------------------------------------------------------------------
    rng = np.random.default_rng([int(seed), 0x5E45])
    noise = effects.is_on("sensor_noise")

    def nz(key: str, m: int) -> np.ndarray:
        return effects.p("sensor_noise", key) * rng.standard_normal(m) if noise else np.zeros(m)

    k_t = float(params["k_t"])
    theta_m = _quantise(col["theta_m"], q_m)
    theta_f = _quantise(col["theta_f"], q_f)
    omega_m = col["omega_m"] + nz("sigma_omega_m", n)
    omega_f = col["omega_f"] + nz("sigma_omega_f", n)
    tau_m = k_t * (col["i_q"] + nz("sigma_i", n))
    Q_true = col["Q_red"]
    if effects.is_on("torque_sensor_bandwidth"):
        Q_true = first_order_lowpass(Q_true, effects.p("torque_sensor_bandwidth", "f_c"), fs)
    Q_red = Q_true + nz("sigma_Q", n)
    if effects.is_on("drive_speed_estimate"):
        omega_m = drive_speed(theta_m, effects.p("drive_speed_estimate", "f_c_m"), fs)
        omega_f = drive_speed(theta_f, effects.p("drive_speed_estimate", "f_c_f"), fs)
    dec = max(1, int(round(fs / 10.0)))
    t_T = t[::dec]
    temps = {}
    for frame, key in zip(TEMPERATURE_FRAMES, ("T_w", "T_h")):
        v = col[key][::dec] + nz("sigma_T", len(t_T))
        temps[frame] = (t_T.copy(), np.round(v, 2))
    keep = np.ones(n, bool)
    t_stamp = t
    if effects.is_on("stamp_jitter"):
        sj = effects.p("stamp_jitter", "sigma")
        if not (0.0 <= sj and math.isfinite(sj)):
            raise ValueError(f"stamp_jitter.sigma = {sj!r} s must be >= 0")
        e = sj * np.random.default_rng([int(seed), 0x717E]).standard_normal(n)
        e[0] = 0.0  # the first stamp stays at the mission start
        t_stamp = t + np.clip(e, -0.45 / fs, 0.45 / fs)
    sig = {"theta_m": theta_m, "theta_f": theta_f, "omega_m": omega_m, "omega_f": omega_f,
           "tau_m": tau_m, "Q_red": Q_red}
    if effects.is_on("dropouts"):
        rate = effects.p("dropouts", "rate")
        mlen = effects.p("dropouts", "mean_len")
        starts = np.flatnonzero(rng.random(n) < rate / fs)
        for s0 in starts:  # few events per mission: loop over events, not samples
            keep[s0:s0 + 1 + int(rng.geometric(1.0 / max(mlen, 1.0)))] = False
        keep[0] = keep[-1] = True
        nst = np.flatnonzero(rng.random(n) < effects.p("dropouts", "nan_rate") / fs)
        names = list(sig)
        for s0 in nst:
            nm = names[int(rng.integers(len(names)))]
            sig[nm] = sig[nm].copy()
            sig[nm][s0:s0 + int(effects.p("dropouts", "nan_len"))] = np.nan
    meta = MissionMeta(
        actuator_id=str(params.get("actuator_id", "EMA-NOM")), mission_index=int(mission_index),
        operating_hours=float(operating_hours), gear_ratio=d["N"], torque_constant=k_t, source="simulation",
        extra={"seed": str(seed), "profile": profile.kind, "simulator": "hd_sim",
               "T_amb": f"{T_amb_:.2f}", "frame_size": "65"},
    )
    mission = Mission(meta=meta, t=t_stamp[keep], theta_m=sig["theta_m"][keep], theta_f=sig["theta_f"][keep],
                      omega_m=sig["omega_m"][keep], omega_f=sig["omega_f"][keep], tau_m=sig["tau_m"][keep],
                      Q_red=sig["Q_red"][keep], t_cmd=t.copy(), theta_ref=profile.theta_ref.copy(),
                      temperatures=temps, t0_ns=0)
    internal = {"t": t[keep]}
    internal.update({k: v[keep] for k, v in col.items()})
    health_out = {
        "h": d["h"], "h_plus": d["h_plus"], "h_minus": d["h_minus"], "h_fail": d["h_fail"],
        "backlash_j": d["backlash_j"], "k_m": d["k_m_eff"], "A2": d["A2"], "mu_c": d["mu_c"], "k_D": d["k_D"],
        "fs_loss": d["fs_loss"], "lube_loss": d["lube_loss"], "K_out_lin": d["K_out_lin"],
    }
    rep = {k: v for k, v in d.items()}
    rep.update({"J_WG_plug": params["J_WG_plug"], "J_rotor": params["J_rotor"], "K_aero_mission": P[K.KI["K_aero"]],
                "c_aero_mission": P[K.KI["c_aero"]], "dt": P[K.KI["dt"]], "n_sub": int(n_sub), "fs": fs,
                "T_amb": T_amb_, "q_f": q_f, "q_m": q_m, "Kp_w": P[K.KI["Kp_w"]], "Ki_w": P[K.KI["Ki_w"]],
                "Kp_p": P[K.KI["Kp_p"]], "actuator_id": meta.actuator_id})
    truth = {
        "internal": internal,
        "health": health_out,
        "effects": {"effects": effects.to_json_dict(), "params": rep, **({"fault": fault_rec} if fault_rec else {})},
        "wear": {"W_plus": float(col["W_plus"][-1]), "W_minus": float(col["W_minus"][-1])},
        "final_state": xf,
    }
    return mission, truth
