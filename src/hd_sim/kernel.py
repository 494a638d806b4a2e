"""Compiled time loop of the plant: EMA (PMSM + cascade control) + three-body harmonic drive + flap.

One function, :func:`integrate`, advances one actuator through a whole
mission with a fixed internal step ``dt`` (default 25 us, 40 sub-steps per
1 kHz log sample) and writes every logged quantity into ``out``. It is
compiled with numba (``cache=True``: the first call in a fresh checkout
compiles for ~10 s, later processes load the cached machine code).

Bodies and coordinates (PHYSICS.md section 1, paper nomenclature):

* wave generator + motor rotor, ``theta_m`` [rad], inertia ``J_WG`` [kg m^2]
  (the total inertia on theta_m: WG plug + rotor; this is the J_WG of r1);
* flexspline radial equivalent ``x_FS`` [m] (unwrapped: x_FS ~ r_b theta_m),
  mass ``m_FSx`` [kg];
* flexspline tangential / torsional equivalent ``y_FS`` [m] at r_m, mass ``m_FSy``;
* circular spline (output flange) ``theta_f`` [rad], inertia ``J_CS``, rigidly
  carrying the flap (inertia ``J_L``) through the output torque sensor, which
  measures ``Q_red = T_L + T_fric_out``, ``T_L = J_L theta_f'' + K_aero theta_f
  + c_aero theta_f' + T_ext``.

Equations integrated (the residuals r1..r4 of PHYSICS.md vanish on them):

    J_WG  theta_m'' = Q_res - F_b r_b
    m_FSx x_FS''    = F_b - F_mx
    m_FSy y_FS''    = -F_FS - F_my
    J_CS  theta_f'' = F_my r_m - Q_red

with the energy-consistent wedge closure of PHYSICS.md 1.2 (mu_g = r_m/(N r_b)):

    delta_b = r_b theta_m - x_FS                   F_b  = k_b delta_b + c_b delta_b'
    delta_m = mu_g x_FS + y_FS - r_m theta_f       F_my = s(theta_m) k_m(h) f(g(delta_m - e_KE; j)) + c_m g' delta_m'
    F_mx = mu_g F_my + mu_c |F_my| tanh(omega_m/eps_v)
    F_FS = k_FS y_FS + c_FS y_FS' + z_h            (z_h: Bouc-Wen state, n = 1)

f is the K1/K2/K3 piecewise mesh law (nonlinear_stiffness) or linear k_m3,
g the smoothed dead zone of total width j (backlash), s the position-dependent
stiffness factor 1 + eps cos(2 theta_m + psi), e_KE = -r_m theta_KE so that at
zero load theta_f = theta_m/N + theta_KE.

Integration: semi-implicit (symplectic) Euler for the mechanics, a
semi-implicit step for the R-L winding, explicit Euler for the thermal states.
The Bouc-Wen state z_h has two steps (``bw_exact``, effect parameter
``hysteresis.exact_step``): 0 = explicit Euler from the sub-step's start state
(the default plant, kept for its recorded bags), 1 = :func:`bouc_wen_step`, the
exact solution for the sub-step's *updated* flexspline speed y_FS' (z then
advances with the same speed as y_FS, so k_FS y + z is a symplectic spring).
The explicit step updates z and y_FS' both from the old state: on the unloading
branch (slope A) that pair is a forward-Euler oscillator, amplified by
sqrt(1 + A dt^2/m_FSy) ~ 1.28 per 25 us step at A_ratio 4; the mesh damping c_m
hides it while the teeth are in contact, but inside a backlash dead zone the
flexspline rings up within a few ms, z leaves +-z_max and the run can
diverge (docs/FAMILIES.md, "Bouc-Wen step").

Logged accelerations are the ones computed from the logged forces at the same
instant, so r1..r4 hold to rounding on ``/sim/internal``.

Mid-mission fault (``flt_*``, built by :func:`hd_sim.plant.fault_vector`):
from internal step ``flt_n_on`` on (``< 0``: no fault) the fault fraction
phi rises linearly from 1/flt_n_ramp to 1 over ``flt_n_ramp`` steps and

    T_C, T_C_out, b_in, b_out, mu_c, mu_bb  x  1 + (flt_fric - 1) phi     (lubrication_loss)
    k_FS                                    x  1 + (flt_kFS - 1) phi      (flexspline_stiffness_loss)
    bw_A; bw_beta = bw_gamma                x  1 + (flt_bwA - 1) phi; 1 + (flt_bwb - 1) phi

(the hysteresis follows k_FS so the loop keeps its catalogue width). Before the
onset no parameter is touched, so the trajectory is bit-identical to the
run without fault. Logged: ``fault_active`` (0/1, 1 from the onset) and
``fault_phi`` (0..1).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Kernel parameter vector layout (all SI). Built by ``hd_sim.plant.kernel_params``.
KNAMES = (
    # bodies and geometry
    "N", "r_m", "r_b", "mu_g", "J_WG", "J_CS", "J_L", "m_FSx", "m_FSy",
    # compliance chain
    "k_b", "c_b", "k_FS", "c_FS", "c_m", "k_m1", "k_m2", "k_m3", "u1", "u2", "km_scale", "nl_on",
    "eps_s", "psi_s", "j_bl", "w_bl",
    "bw_A", "bw_beta", "bw_gamma", "hyst_on",
    "mu_c",
    # kinematic error (output rad)
    "A1", "A2", "A4", "psi1", "psi2", "psi4", "a_T", "T_rated", "B1", "B2", "chi1", "chi2",
    # input-side friction and position torques
    "T_C", "T_S_ratio", "omega_s", "delta_s", "stribeck_on", "b_in",
    "F1", "F2", "F3", "F4", "rho1", "rho2", "rho3", "rho4",
    "nu_beta", "T_ref", "n_b", "n_c", "tdf_on", "eps_v", "mu_bb",
    "P1", "P2", "phi_p1", "phi_p2",
    "C1", "C2", "N_c", "phi_c1", "phi_c2",
    "r6", "r12", "phi_r6", "phi_r12",
    # output-side friction and load
    "T_C_out", "b_out", "K_aero", "c_aero",
    # motor
    "p", "R0", "L", "psi_m", "alpha_R", "alpha_psi", "drift_on", "V_max", "i_max", "psi_hat", "R_hat",
    # control
    "Kp_i", "Ki_i", "Kp_w", "Ki_w", "Kp_p", "omega_max_f", "n_ctrl", "q_f", "input_locked",
    # thermal
    "C_w", "R_wh", "C_h", "R_ha", "heat_on",
    # mid-mission fault (hd_sim.plant.fault_vector): onset step, ramp steps, final multipliers
    "flt_n_on", "flt_n_ramp", "flt_fric", "flt_kFS", "flt_bwA", "flt_bwb",
    # switchable laws (hd_sim.effects.LAW_SLOTS): friction transition 0 = tanh(omega/eps_v) (hard sign
    # at the default eps_v, smooth at a wide one), 1 = LuGre (bristle stiffness/damping sigma0, sigma1);
    # torsion 0 = three-slope/linear mesh_law, 1 = cubic mesh spring k_m1 u + k_cub u^3
    "fric_law", "lg_sigma0", "lg_sigma1", "tors_law", "k_cub",
    # numerics; bw_exact: Bouc-Wen step (0 explicit Euler as recorded, 1 exact step, see module doc)
    "dt", "n_sub", "bw_exact",
)
KI = {n: i for i, n in enumerate(KNAMES)}

#: Initial-state vector layout.
SNAMES = ("theta_m", "omega_m", "x_FS", "x_FS_d", "y_FS", "y_FS_d", "theta_f", "omega_f", "z_h",
          "i_d", "i_q", "T_w", "T_h", "I_w", "I_d", "I_q", "z_lg")
SI = {n: i for i, n in enumerate(SNAMES)}

#: Logged columns, one row per log sample (the /sim/internal names first).
OUT_NAMES = (
    "theta_m", "theta_f", "omega_m", "omega_f", "alpha_m", "alpha_f",
    "x_FS", "y_FS", "x_FS_dd", "y_FS_dd", "F_b", "F_mx", "F_my", "F_FS",
    "Q_res", "Q_red", "T_L", "T_fric_in", "T_fric_out", "theta_KE", "i_q", "i_d", "T_w", "T_h",
    # extras (also written to /sim/internal)
    "x_FS_d", "y_FS_d", "z_h", "T_e", "T_cog", "T_pos", "T_ext", "T_tr", "k_m_eff",
    "v_d", "v_q", "i_q_ref", "omega_m_ref",
    "W_in", "W_ext", "W_pos", "W_diss", "W_plus", "W_minus",
    "fault_active", "fault_phi",
    # LuGre bristle state [rad at the motor] (0 under the tanh friction law)
    "z_lg",
)
OI = {n: i for i, n in enumerate(OUT_NAMES)}


def _consts() -> None:
    g = globals()
    for n, i in KI.items():
        g["K_" + n] = i
    for n, i in SI.items():
        g["S_" + n] = i
    for n, i in OI.items():
        g["O_" + n] = i


_consts()


@njit(cache=True, inline="always")
def _softplus(a):
    if a > 30.0:
        return a
    if a < -30.0:
        return math.exp(a)
    return math.log1p(math.exp(a))


@njit(cache=True, inline="always")
def _sigmoid(a):
    if a >= 0.0:
        return 1.0 / (1.0 + math.exp(-a))
    e = math.exp(a)
    return e / (1.0 + e)


@njit(cache=True, inline="always")
def bouc_wen_step(z, v, A, beta, gamma, dt):
    """Exact step of dz/dt = A v - beta |v| z - gamma v |z| (Bouc-Wen, n = 1) with v held over dt.

    For a held v the law is linear in z on each branch: loading (z v >= 0) relaxes z to
    z_ss = A v / ((beta + gamma)|v|) at the rate (beta + gamma)|v|; unloading (z v < 0) moves z
    towards 0 at the rate (beta - gamma)|v| (linearly, slope A v, when beta = gamma) and, once z
    crosses 0 inside the step, the rest of the step is loading. Closed form on each piece, so
    |z| never exceeds max(|z0|, A/(beta + gamma)) whatever |v| dt (the explicit Euler step
    overshoots once (beta + gamma)|v| dt > 2).
    """
    if v == 0.0 or dt <= 0.0:
        return z
    av = abs(v)
    if z * v < 0.0:  # unloading: z heads for 0
        r_u = (beta - gamma) * av
        if abs(r_u) * dt < 1e-12:
            t0 = -z / (A * v)
            if t0 >= dt:
                return z + A * v * dt
        else:
            z_u = A * v / r_u
            ratio = z_u / (z_u - z)
            t0 = -math.log(ratio) / r_u if 0.0 < ratio < math.inf else math.inf
            if not (t0 < dt):
                return z_u + (z - z_u) * math.exp(-r_u * dt)
        dt = dt - t0
        z = 0.0
    r_l = (beta + gamma) * av  # loading (z v >= 0)
    if r_l * dt < 1e-12:
        return z + A * v * dt
    z_ss = A * v / r_l
    return z_ss + (z - z_ss) * math.exp(-r_l * dt)


@njit(cache=True)
def mesh_law(ug, k1, k2, k3, u1, u2, nl_on):
    """Elastic mesh force [N] for a mesh deflection ug [m] (after the dead zone)."""
    if nl_on < 0.5:
        return k3 * ug
    a = abs(ug)
    if a <= u1:
        f = k1 * a
    elif a <= u2:
        f = k1 * u1 + k2 * (a - u1)
    else:
        f = k1 * u1 + k2 * (u2 - u1) + k3 * (a - u2)
    return f if ug >= 0.0 else -f


@njit(cache=True)
def integrate(P, x0, theta_ref, omega_ff, T_ext, T_amb, out):  # noqa: C901 - one loop on purpose
    """Advance one actuator over ``len(theta_ref)`` log samples.

    P: kernel parameters (layout ``KNAMES``); x0: initial state (``SNAMES``);
    theta_ref [rad] and omega_ff [rad/s] (output command and its feed-forward
    rate, one per log sample, held between samples); T_ext [N m] external
    hinge moment per log sample (linearly interpolated); T_amb [degC];
    out: float64[n_log, len(OUT_NAMES)], filled in place. Returns the final state.
    """
    N = P[K_N]; r_m = P[K_r_m]; r_b = P[K_r_b]; mu_g = P[K_mu_g]
    J_WG = P[K_J_WG]; J_CS = P[K_J_CS]; J_L = P[K_J_L]; m_x = P[K_m_FSx]; m_y = P[K_m_FSy]
    k_b = P[K_k_b]; c_b = P[K_c_b]; k_FS = P[K_k_FS]; c_FS = P[K_c_FS]; c_m = P[K_c_m]
    k1 = P[K_k_m1]; k2 = P[K_k_m2]; k3 = P[K_k_m3]; u1 = P[K_u1]; u2 = P[K_u2]
    km_scale = P[K_km_scale]; nl_on = P[K_nl_on]; eps_s = P[K_eps_s]; psi_s = P[K_psi_s]
    j_bl = P[K_j_bl]; w_bl = P[K_w_bl]
    bw_A = P[K_bw_A]; bw_beta = P[K_bw_beta]; bw_gamma = P[K_bw_gamma]; hyst_on = P[K_hyst_on]
    mu_c = P[K_mu_c]
    A1 = P[K_A1]; A2 = P[K_A2]; A4 = P[K_A4]; psi1 = P[K_psi1]; psi2 = P[K_psi2]; psi4 = P[K_psi4]
    a_T = P[K_a_T]; T_rated = P[K_T_rated]; B1 = P[K_B1]; B2 = P[K_B2]; chi1 = P[K_chi1]; chi2 = P[K_chi2]
    T_C0 = P[K_T_C]; T_S_ratio = P[K_T_S_ratio]; omega_s = P[K_omega_s]; delta_s = P[K_delta_s]
    stribeck_on = P[K_stribeck_on]; b_in0 = P[K_b_in]
    F1 = P[K_F1]; F2 = P[K_F2]; F3 = P[K_F3]; F4 = P[K_F4]
    rho1 = P[K_rho1]; rho2 = P[K_rho2]; rho3 = P[K_rho3]; rho4 = P[K_rho4]
    nu_beta = P[K_nu_beta]; T_ref = P[K_T_ref]; n_b = P[K_n_b]; n_c = P[K_n_c]; tdf_on = P[K_tdf_on]
    eps_v = P[K_eps_v]; mu_bb = P[K_mu_bb]
    P1 = P[K_P1]; P2 = P[K_P2]; phi_p1 = P[K_phi_p1]; phi_p2 = P[K_phi_p2]
    C1 = P[K_C1]; C2 = P[K_C2]; N_c = P[K_N_c]; phi_c1 = P[K_phi_c1]; phi_c2 = P[K_phi_c2]
    r6 = P[K_r6]; r12 = P[K_r12]; phi_r6 = P[K_phi_r6]; phi_r12 = P[K_phi_r12]
    T_C_out0 = P[K_T_C_out]; b_out0 = P[K_b_out]; K_aero = P[K_K_aero]; c_aero = P[K_c_aero]
    pp = P[K_p]; R0 = P[K_R0]; L = P[K_L]; psi_m0 = P[K_psi_m]; alpha_R = P[K_alpha_R]
    alpha_psi = P[K_alpha_psi]; drift_on = P[K_drift_on]; V_max = P[K_V_max]; i_max = P[K_i_max]
    psi_hat = P[K_psi_hat]; R_hat = P[K_R_hat]
    Kp_i = P[K_Kp_i]; Ki_i = P[K_Ki_i]; Kp_w = P[K_Kp_w]; Ki_w = P[K_Ki_w]; Kp_p = P[K_Kp_p]
    omega_max_f = P[K_omega_max_f]; n_ctrl = int(P[K_n_ctrl]); q_f = P[K_q_f]
    locked = P[K_input_locked] > 0.5
    C_w = P[K_C_w]; R_wh = P[K_R_wh]; C_h = P[K_C_h]; R_ha = P[K_R_ha]; heat_on = P[K_heat_on]
    dt = P[K_dt]; n_sub = int(P[K_n_sub]); bw_exact = P[K_bw_exact] > 0.5
    flt_n_on = P[K_flt_n_on]; flt_n_ramp = max(P[K_flt_n_ramp], 1.0)
    flt_fric = P[K_flt_fric]; flt_kFS = P[K_flt_kFS]; flt_bwA = P[K_flt_bwA]; flt_bwb = P[K_flt_bwb]
    bw_A0 = bw_A; bw_beta0 = bw_beta; bw_gamma0 = bw_gamma
    T_C00 = T_C0; T_C_out00 = T_C_out0; b_in00 = b_in0; b_out00 = b_out0; mu_c0 = mu_c; mu_bb0 = mu_bb
    k_FS0 = k_FS
    fric_law = P[K_fric_law]; lg_s0 = P[K_lg_sigma0]; lg_s1 = P[K_lg_sigma1]
    tors_law = P[K_tors_law]; k_cub = P[K_k_cub]
    lugre = fric_law > 0.5
    cubic = tors_law > 0.5
    g_lg = 1.0
    phi = 0.0; f_on = 0.0
    J_out = J_CS + J_L
    eps_vf = eps_v / N

    th_m = x0[S_theta_m]; w_m = x0[S_omega_m]; x = x0[S_x_FS]; vx = x0[S_x_FS_d]
    y = x0[S_y_FS]; vy = x0[S_y_FS_d]; th_f = x0[S_theta_f]; w_f = x0[S_omega_f]; z = x0[S_z_h]
    i_d = x0[S_i_d]; i_q = x0[S_i_q]; T_w = x0[S_T_w]; T_h = x0[S_T_h]
    I_w = x0[S_I_w]; I_d = x0[S_I_d]; I_q = x0[S_I_q]; z_lg = x0[S_z_lg]

    n_log = theta_ref.shape[0]
    W_in = 0.0; W_ext = 0.0; W_pos = 0.0; W_diss = 0.0; W_plus = 0.0; W_minus = 0.0
    i_q_ref = i_q; w_m_ref = 0.0
    T_tr_prev = 0.0
    fb = 1.0; fc = 1.0
    R = R0; psi = psi_m0
    v_d = 0.0; v_q = 0.0
    dt_c = dt * n_ctrl
    step = 0
    for k in range(n_log):
        for s in range(n_sub):
            # ---- mid-mission fault: ramp the affected parameters (never before the onset) ---
            if flt_n_on >= 0.0 and phi < 1.0 and step >= flt_n_on:
                f_on = 1.0
                phi = min(1.0, (step - flt_n_on + 1.0) / flt_n_ramp)
                mf = 1.0 + (flt_fric - 1.0) * phi
                T_C0 = T_C00 * mf; T_C_out0 = T_C_out00 * mf; b_in0 = b_in00 * mf; b_out0 = b_out00 * mf
                mu_c = mu_c0 * mf; mu_bb = mu_bb0 * mf
                k_FS = k_FS0 * (1.0 + (flt_kFS - 1.0) * phi)
                bw_A = bw_A0 * (1.0 + (flt_bwA - 1.0) * phi)
                mb = 1.0 + (flt_bwb - 1.0) * phi
                bw_beta = bw_beta0 * mb; bw_gamma = bw_gamma0 * mb
            # ---- slow quantities at the control rate -------------------------------------
            if step % n_ctrl == 0:
                if tdf_on > 0.5:
                    nu_ratio = math.exp(-nu_beta * (T_h - T_ref))
                    fb = nu_ratio ** n_b
                    fc = nu_ratio ** n_c
                if drift_on > 0.5:
                    R = R0 * (1.0 + alpha_R * (T_w - 20.0))
                    psi = psi_m0 * (1.0 - alpha_psi * (T_w - 20.0))
                # position loop on the (quantised) load encoder, speed PI on the motor
                th_f_meas = th_f if q_f <= 0.0 else q_f * math.floor(th_f / q_f + 0.5)
                w_f_cmd = Kp_p * (theta_ref[k] - th_f_meas) + omega_ff[k]
                if w_f_cmd > omega_max_f:
                    w_f_cmd = omega_max_f
                elif w_f_cmd < -omega_max_f:
                    w_f_cmd = -omega_max_f
                w_m_ref = N * w_f_cmd
                e_w = w_m_ref - w_m
                iq_u = Kp_w * e_w + I_w
                if iq_u > i_max:
                    i_q_ref = i_max
                    if e_w < 0.0:
                        I_w += Ki_w * e_w * dt_c
                elif iq_u < -i_max:
                    i_q_ref = -i_max
                    if e_w > 0.0:
                        I_w += Ki_w * e_w * dt_c
                else:
                    i_q_ref = iq_u
                    I_w += Ki_w * e_w * dt_c
            # ---- kinematic error and mesh ------------------------------------------------
            sm = math.sin(th_m); cm = math.cos(th_m)
            s2 = 2.0 * sm * cm; c2 = cm * cm - sm * sm
            s4 = 2.0 * s2 * c2; c4 = c2 * c2 - s2 * s2
            A2e = A2 * (1.0 + a_T * abs(T_tr_prev) / T_rated)
            th_ke = 0.0
            if A1 != 0.0:
                th_ke += A1 * (sm * math.cos(psi1) + cm * math.sin(psi1))
            if A2e != 0.0:
                th_ke += A2e * (s2 * math.cos(psi2) + c2 * math.sin(psi2))
            if A4 != 0.0:
                th_ke += A4 * (s4 * math.cos(psi4) + c4 * math.sin(psi4))
            if B1 != 0.0:
                th_ke += B1 * math.sin(th_f + chi1)
            if B2 != 0.0:
                th_ke += B2 * math.sin(2.0 * th_f + chi2)
            e_ke = -r_m * th_ke
            d_b = r_b * th_m - x
            d_b_d = r_b * w_m - vx
            d_m = mu_g * x + y - r_m * th_f
            d_m_d = mu_g * vx + vy - r_m * w_f
            u = d_m - e_ke
            if j_bl > 0.0:
                hj = 0.5 * j_bl
                ug = w_bl * (_softplus((u - hj) / w_bl) - _softplus((-u - hj) / w_bl))
                dg = _sigmoid((u - hj) / w_bl) + _sigmoid((-u - hj) / w_bl)
            else:
                ug = u
                dg = 1.0
            ks = km_scale
            if eps_s != 0.0:
                ks = km_scale * (1.0 + eps_s * (c2 * math.cos(psi_s) - s2 * math.sin(psi_s)))
            if cubic:
                F_el = ks * (k1 + k_cub * ug * ug) * ug
            else:
                F_el = ks * mesh_law(ug, k1, k2, k3, u1, u2, nl_on)
            F_my = F_el + c_m * dg * d_m_d
            sgn_m = math.tanh(w_m / eps_v)
            F_mx = mu_g * F_my + mu_c * abs(F_my) * sgn_m
            F_FS = k_FS * y + c_FS * vy
            if hyst_on > 0.5:
                F_FS += z
            F_b = k_b * d_b + c_b * d_b_d
            # ---- torques -------------------------------------------------------------------
            rip = 1.0
            if r6 != 0.0:
                rip += r6 * math.cos(6.0 * pp * th_m + phi_r6)
            if r12 != 0.0:
                rip += r12 * math.cos(12.0 * pp * th_m + phi_r12)
            kt = 1.5 * pp * psi
            T_e = kt * i_q * rip
            T_cog = 0.0
            if C1 != 0.0:
                T_cog += C1 * math.sin(N_c * th_m + phi_c1)
            if C2 != 0.0:
                T_cog += C2 * math.sin(2.0 * N_c * th_m + phi_c2)
            T_pos = 0.0
            if P1 != 0.0:
                T_pos += P1 * (sm * math.cos(phi_p1) + cm * math.sin(phi_p1))
            if P2 != 0.0:
                T_pos += P2 * (s2 * math.cos(phi_p2) + c2 * math.sin(phi_p2))
            Tc = T_C0 * fc
            fr = Tc
            if stribeck_on > 0.5:
                fr += (T_S_ratio - 1.0) * Tc * math.exp(-(abs(w_m) / omega_s) ** delta_s)
            if lugre:
                g_lg = max(fr, 1e-9)  # LuGre steady-state sliding torque g(omega_m): Coulomb + Stribeck
            if F1 != 0.0:
                fr += F1 * (sm * math.cos(rho1) + cm * math.sin(rho1))
            if F2 != 0.0:
                fr += F2 * (s2 * math.cos(rho2) + c2 * math.sin(rho2))
            if F3 != 0.0:
                fr += F3 * math.sin(3.0 * th_m + rho3)
            if F4 != 0.0:
                fr += F4 * (s4 * math.cos(rho4) + c4 * math.sin(rho4))
            if mu_bb != 0.0:
                fr += mu_bb * r_b * abs(F_b)
            if lugre:
                zd_lg = w_m - lg_s0 * abs(w_m) * z_lg / g_lg
                T_fin = lg_s0 * z_lg + lg_s1 * zd_lg + (fr - g_lg) * sgn_m + b_in0 * fb * w_m
            else:
                T_fin = fr * sgn_m + b_in0 * fb * w_m
            sgn_f = math.tanh(w_f / eps_vf)
            T_fout = T_C_out0 * fc * sgn_f + b_out0 * fb * w_f
            T_ex = T_ext[k]
            if k + 1 < n_log:
                T_ex += (T_ext[k + 1] - T_ext[k]) * (s / n_sub)
            T_ld = K_aero * th_f + c_aero * w_f + T_ex
            if locked:
                Q_res = F_b * r_b
                a_m = 0.0
            else:
                Q_res = T_e - T_fin - T_cog - T_pos
                a_m = (Q_res - F_b * r_b) / J_WG
            a_x = (F_b - F_mx) / m_x
            a_y = (-F_FS - F_my) / m_y
            a_f = (F_my * r_m - T_fout - T_ld) / J_out
            T_tr = F_my * r_m
            # ---- log at the sample instant -----------------------------------------------
            if s == 0:
                T_L = J_L * a_f + T_ld
                o = out[k]
                o[O_theta_m] = th_m; o[O_theta_f] = th_f; o[O_omega_m] = w_m; o[O_omega_f] = w_f
                o[O_alpha_m] = a_m; o[O_alpha_f] = a_f; o[O_x_FS] = x; o[O_y_FS] = y
                o[O_x_FS_dd] = a_x; o[O_y_FS_dd] = a_y; o[O_F_b] = F_b; o[O_F_mx] = F_mx
                o[O_F_my] = F_my; o[O_F_FS] = F_FS; o[O_Q_res] = Q_res; o[O_Q_red] = T_L + T_fout
                o[O_T_L] = T_L; o[O_T_fric_in] = T_fin; o[O_T_fric_out] = T_fout; o[O_theta_KE] = th_ke
                o[O_i_q] = i_q; o[O_i_d] = i_d; o[O_T_w] = T_w; o[O_T_h] = T_h
                o[O_x_FS_d] = vx; o[O_y_FS_d] = vy; o[O_z_h] = z; o[O_T_e] = T_e; o[O_T_cog] = T_cog
                o[O_T_pos] = T_pos; o[O_T_ext] = T_ex; o[O_T_tr] = T_tr
                if cubic:
                    o[O_k_m_eff] = ks * (k1 + 3.0 * k_cub * ug * ug)
                else:
                    o[O_k_m_eff] = ks * (k3 if nl_on < 0.5 else (k1 if abs(ug) <= u1 else (k2 if abs(ug) <= u2 else k3)))
                o[O_v_d] = v_d; o[O_v_q] = v_q; o[O_i_q_ref] = i_q_ref; o[O_omega_m_ref] = w_m_ref
                o[O_W_in] = W_in; o[O_W_ext] = W_ext; o[O_W_pos] = W_pos; o[O_W_diss] = W_diss
                o[O_W_plus] = W_plus; o[O_W_minus] = W_minus
                o[O_fault_active] = f_on; o[O_fault_phi] = phi
                o[O_z_lg] = z_lg
            # ---- power bookkeeping (energy balance, wear and heat) ---------------------------
            p_mesh_fric = mu_c * abs(F_my) * sgn_m * vx
            p_diss = (T_fin * w_m + T_fout * w_f + c_b * d_b_d * d_b_d + c_m * dg * d_m_d * d_m_d
                      + c_FS * vy * vy + p_mesh_fric)
            if hyst_on > 0.5:
                p_diss += z * vy
            if locked:
                p_diss -= T_fin * w_m
            W_in += (0.0 if locked else T_e * w_m) * dt
            W_ext += T_ld * w_f * dt
            W_pos += (T_cog + T_pos) * w_m * dt
            W_diss += p_diss * dt
            aw = abs(w_m) * dt
            if T_tr > 0.0:
                W_plus += T_tr * aw
            else:
                W_minus -= T_tr * aw
            T_tr_prev = T_tr
            # ---- current loop and winding ----------------------------------------------------
            if not locked:
                e_d = -i_d
                e_q = i_q_ref - i_q
                vd_u = Kp_i * e_d + I_d - pp * w_m * L * i_q
                vq_u = Kp_i * e_q + I_q + pp * w_m * (L * i_d + psi_hat)
                mag = math.sqrt(vd_u * vd_u + vq_u * vq_u)
                if mag > V_max:
                    v_d = vd_u * V_max / mag
                    v_q = vq_u * V_max / mag
                else:
                    v_d = vd_u
                    v_q = vq_u
                    I_d += Ki_i * e_d * dt
                    I_q += Ki_i * e_q * dt
                g = dt / L
                i_d = (i_d + g * (v_d + pp * w_m * L * i_q)) / (1.0 + R * g)
                i_q = (i_q + g * (v_q - pp * w_m * (L * i_d + psi))) / (1.0 + R * g)
            # ---- mechanics (semi-implicit Euler) ---------------------------------------------
            if hyst_on > 0.5 and not bw_exact:  # explicit Euler from the old state (as recorded)
                z += dt * (bw_A * vy - bw_beta * abs(vy) * z - bw_gamma * vy * abs(z))
            if lugre:
                # exact step of dz/dt = w - sigma0 |w| z / g for w, g frozen over dt (stable at any speed)
                r_lg = lg_s0 * abs(w_m) / g_lg
                if r_lg * dt > 1e-12:
                    z_ss = math.copysign(g_lg / lg_s0, w_m)
                    z_lg = z_ss + (z_lg - z_ss) * math.exp(-r_lg * dt)
            w_m += a_m * dt
            vx += a_x * dt
            vy += a_y * dt
            if hyst_on > 0.5 and bw_exact:  # exact step at the updated speed, as y_FS below
                z = bouc_wen_step(z, vy, bw_A, bw_beta, bw_gamma, dt)
            w_f += a_f * dt
            th_m += w_m * dt
            x += vx * dt
            y += vy * dt
            th_f += w_f * dt
            # ---- thermal nodes -----------------------------------------------------------------
            if heat_on > 0.5:
                P_cu = 1.5 * R * (i_d * i_d + i_q * i_q)
                q_wh = (T_w - T_h) / R_wh
                T_w += dt * (P_cu - q_wh) / C_w
                T_h += dt * (p_diss + q_wh - (T_h - T_amb) / R_ha) / C_h
            step += 1
    xf = np.empty(len(x0))
    xf[S_theta_m] = th_m; xf[S_omega_m] = w_m; xf[S_x_FS] = x; xf[S_x_FS_d] = vx
    xf[S_y_FS] = y; xf[S_y_FS_d] = vy; xf[S_theta_f] = th_f; xf[S_omega_f] = w_f; xf[S_z_h] = z
    xf[S_i_d] = i_d; xf[S_i_q] = i_q; xf[S_T_w] = T_w; xf[S_T_h] = T_h
    xf[S_I_w] = I_w; xf[S_I_d] = I_d; xf[S_I_q] = I_q; xf[S_z_lg] = z_lg
    return xf


@njit(cache=True)
def rate_limit(target, dt, rate_max, acc_max, x0):
    """Second-order command shaper: follow ``target`` with |v| <= rate_max, |a| <= acc_max.

    A sampled-data time-optimal-ish tracker (brake when the stopping distance
    reaches the remaining error). Returns (position, velocity) arrays.
    """
    n = target.shape[0]
    pos = np.empty(n)
    vel = np.empty(n)
    p = x0
    v = 0.0
    for i in range(n):
        e = target[i] - p
        # velocity that stops exactly at the target under acc_max
        v_des = math.copysign(math.sqrt(2.0 * acc_max * abs(e)), e)
        if v_des > rate_max:
            v_des = rate_max
        elif v_des < -rate_max:
            v_des = -rate_max
        dv = v_des - v
        lim = acc_max * dt
        if dv > lim:
            dv = lim
        elif dv < -lim:
            dv = -lim
        v += dv
        p += v * dt
        pos[i] = p
        vel[i] = v
    return pos, vel
