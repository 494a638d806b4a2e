"""ema2: an electromechanical flap actuator with a strain-wave gear, written from scratch for tests.

This module shares no code and no conventions with the project's own simulator: it imports numpy,
the standard library and (for writing bags only) ``mcap`` / ``mcap-ros2-support``, nothing of ours.
It exists so that estimators are tested on data they were not built around. See README.md here for
the laws, the parameter values and their sources, and the effect list.

Model (SI units; motor side "m", flap / output side "f"; N = reduction ratio)::

    twist       w   = theta_m / N - theta_f                          (rad, at the output)
    transmitted Q   = k1(theta_m) * w_e + k3 * w_e**3 + c_t * dw_e    (N*m; w_e = w outside the dead zone)
    motor       J_m omega_m' = k_t i_q + T_ripple(theta_m) - T_fric(omega_m, T, |Q|) - (Q + T_out(theta_f)) / N
    flap        J_f omega_f' = Q - K_aero theta_f - c_aero omega_f - T_gust(t)
    friction    T_fric = (F_c + F_str exp(-(omega/v_s)^2) + mu_L |Q| / N) tanh(omega / v_t) + b(T) omega
    current     i_q' = (i_ref - i_q) / tau_i, |i_ref| <= i_max         (current loop as a first-order lag)
    control     omega_ref = N (Kp_x (theta_ref - theta_f,meas) + theta_ref'), |omega_ref| <= omega_max
                i_ref = (Kp_w e_w + Ki_w integral e_w) / k_t,  e_w = omega_ref - omega_m,est

Integrator: semi-implicit (symplectic) Euler at ``internal_rate`` (default 4 kHz, an integer multiple of
the sample rate), the exact exponential step for the current lag; the drive's speed estimate is a
first-order filtered difference of the quantised encoder. Output decimated (instantaneous samples) to
``sample_rate`` (default 1 kHz). Many missions run at once as a batch (numpy arrays over the batch).

Sign convention: positive Q drives the flap towards positive theta_f and has the sign of the wind-up w
(as the bag contract wants: theta_m = N theta_f + compliance).
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

# ---------------------------------------------------------------------------------------------
# parameters
# ---------------------------------------------------------------------------------------------

#: Base plant: a size-32-class strain-wave gear, ratio 80, on a flap EMA (README.md: sources).
BASE = {
    "N": 80.0,  # reduction ratio (motor turns per output turn)
    "k_t": 0.28,  # N*m/A motor torque constant
    "J_m": 3.0e-4,  # kg*m^2 motor rotor + wave generator
    "J_f": 0.25,  # kg*m^2 flap + output flange
    "K_aero": 350.0,  # N*m/rad aerodynamic hinge stiffness
    "c_aero": 2.0,  # N*m*s/rad flap damping
    "gust_rms": 8.0,  # N*m band-limited gust torque on the flap (unmeasured)
    "k1": 8.1e4,  # N*m/rad linear torsional stiffness
    "k3": 8.0e9,  # N*m/rad^3 cubic hardening
    "c_t": 8.0,  # N*m*s/rad structural damping of the flexspline
    "F_c": 0.06,  # N*m Coulomb friction at the motor (gear no-load running torque, reflected)
    "v_t": 1.0,  # rad/s width of the tanh transition through zero motor speed
    "b_ref": 8.0e-4,  # N*m*s/rad viscous friction at the motor at T_ref
    "T_ref": 25.0,  # degC
    "tau_i": 5.0e-4,  # s current-loop time constant
    "i_max": 12.0,  # A current limit
    "omega_max": 350.0,  # rad/s motor speed limit
    "Kp_x": 40.0,  # 1/s position gain (output angle -> output speed)
    "wc_w": 2 * math.pi * 40.0,  # rad/s speed-loop crossover
    "tau_w": 1.0e-3,  # s drive speed-estimate filter
    "enc_m_bits": 16,  # motor encoder counts per revolution = 2**bits
    "enc_f_bits": 20,  # output (flap) encoder counts per revolution
    "i_noise": 0.03,  # A rms current-measurement noise (0.25 % of i_max)
    "i_lsb": 24.0 / 4096,  # A current ADC resolution (12 bit over +-12 A)
    "Q_noise": 0.3,  # N*m rms torque-sensor noise
    "Q_lsb": 0.05,  # N*m torque-sensor resolution
    "temp_noise": 0.05,  # K temperature-sensor noise
    "temp_lsb": 0.1,  # K temperature-sensor resolution
    "temp_rate": 10.0,  # Hz temperature topic rate
}

#: Undeclared effects, one parameter set each (all zero = absent). Units in README.md.
EFFECT_PARAMS0 = {
    "ripple_amp": 0.0, "ripple_phase": 0.6,  # N*m at the motor, 2 per motor revolution
    "visc_temp_coeff": 0.0,  # 1/K: b(T) = b_ref exp(-c (T - T_ref))
    "stribeck_rise": 0.0, "stribeck_speed": 5.0,  # N*m, rad/s at the motor
    "load_friction": 0.0,  # mu_L: friction grows by mu_L * |Q| / N
    "out_amp": 0.0, "out_order": 3.0, "out_phase": 0.9,  # N*m at the output, cycles per output revolution
    "dead_zone": 0.0,  # rad half-width of the lost motion (at the output)
    "stiff_mod": 0.0, "stiff_phase": 0.4,  # relative stiffness modulation, 2 per wave-generator revolution
}

EFFECTS = {
    "clean": {},
    "ripple": {"ripple_amp": 0.04},
    "ripple_weak": {"ripple_amp": 0.012},
    "temp_viscosity": {"visc_temp_coeff": 0.03},
    "stribeck": {"stribeck_rise": 0.05},
    "load_friction": {"load_friction": 0.06},
    "output_periodic": {"out_amp": 6.0},
    "dead_zone": {"dead_zone": 2.0e-4},
    "position_stiffness": {"stiff_mod": 0.12},
    "ripple_temp_viscosity": {"ripple_amp": 0.04, "visc_temp_coeff": 0.03},
}

#: Which recorded signal each effect shows in first (for the tests and for scoring).
EFFECT_SIGNAL = {
    "clean": None, "ripple": "tau_m", "ripple_weak": "tau_m", "temp_viscosity": "tau_m", "stribeck": "tau_m",
    "load_friction": "tau_m", "output_periodic": "tau_m", "dead_zone": "Q_red", "position_stiffness": "Q_red",
    "ripple_temp_viscosity": "tau_m",
}

#: Wear: how a wear depth d (m) shows (d_ref = nominal failure depth).
WEAR = {
    "d_ref": 40e-6,  # m nominal wear depth at failure
    "friction_gain": 0.8,  # F_c (1 + g d / d_ref)
    "lost_motion_gain": 1.5e-4,  # rad dead-zone half-width per d_ref of wear
    "stiffness_loss": 0.25,  # k1 (1 - s d / d_ref)
    "accel": 0.5,  # wear rate grows with (1 + a d / d_ref)
    "rate_scatter": 0.25,  # log-normal sigma of the unit wear rate
    "threshold_scatter": 0.08,  # log-normal sigma of the unit failure depth
    "E_ref_per_s": 20.0,  # W: typical mean of |Q omega_f| over a mission (sets the exposure scale)
}

DEFAULT_SAMPLE_RATE = 1000.0
DEFAULT_INTERNAL_RATE = 4000.0
DEFAULT_DURATION = 60.0


def effect_spec(effect: str, params: dict | None = None) -> dict:
    """The named effect's changed parameters with ``params`` overriding them (e.g. {"ripple_amp": 0.02})."""
    if effect not in EFFECTS:
        raise ValueError(f"ema2: unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
    spec = dict(EFFECTS[effect], **(params or {}))
    effect_params(spec)  # checks the keys
    return spec


def effect_params(effect: str | dict) -> dict:
    """Full effect parameter set for a named effect (or a dict of overrides on 'clean')."""
    p = dict(EFFECT_PARAMS0)
    if isinstance(effect, str):
        if effect not in EFFECTS:
            raise ValueError(f"ema2: unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
        p.update(EFFECTS[effect])
    else:
        unknown = set(effect) - set(EFFECT_PARAMS0)
        if unknown:
            raise ValueError(f"ema2: unknown effect parameters {sorted(unknown)}")
        p.update(effect)
    return p


# ---------------------------------------------------------------------------------------------
# mission profile (reference, temperature, gusts)
# ---------------------------------------------------------------------------------------------

def reference(duration: float, fs: float, rng: np.random.Generator, stroke: float = 0.44) -> np.ndarray:
    """A varied flap command: sines, steps, constant-speed ramps both ways, holds, dither; smooth."""
    n = int(round(duration * fs))
    t = np.arange(n) / fs
    target = np.zeros(n)
    kinds = ["sines", "ramps", "steps", "hold", "dither"]
    i, x, order = int(0.5 * fs), 0.0, []
    # the first three segments are sines, ramps and steps in random order, shortened so that all three fit
    # into missions from 6 s on; then all five kinds in random order
    first = min(4.5, max(1.0, (duration - 0.5) / 3.0))
    k_seg = 0
    while i < n:
        if not order:
            order = list(rng.permutation(kinds[:3])) + list(rng.permutation(kinds))
        kind = order.pop(0)
        hi = first if k_seg < 3 else 4.5
        L = min(n - i, int(rng.uniform(min(2.0, 0.7 * hi), hi) * fs))
        k_seg += 1
        tt = np.arange(L) / fs
        if kind == "sines":
            k = rng.integers(2, 4)
            f = rng.uniform(0.15, 1.2, k)
            a = rng.dirichlet(np.ones(k)) * rng.uniform(0.15, 0.38)
            ph = rng.uniform(0, 2 * np.pi, k)
            seg = x + np.sum(a[:, None] * (np.sin(2 * np.pi * f[:, None] * tt + ph[:, None]) - np.sin(ph[:, None])), 0)
        elif kind == "ramps":
            v = rng.uniform(0.05, 0.6) * rng.choice([-1, 1])
            seg = np.empty(L)
            y = x
            for j in range(L):  # triangle between +-0.9 stroke at constant speed
                y += v / fs
                if abs(y) > 0.9 * stroke:
                    v = -v
                    y += 2 * v / fs
                seg[j] = y
        elif kind == "steps":
            seg = np.empty(L)
            j = 0
            while j < L:
                m = int(rng.uniform(0.5, 1.5) * fs)
                seg[j:j + m] = rng.uniform(-0.9, 0.9) * stroke
                j += m
        elif kind == "hold":
            seg = np.full(L, x)
        else:  # dither: small stroke around a random level, repeatedly through zero speed
            lvl = rng.uniform(-0.6, 0.6) * stroke
            seg = lvl + rng.uniform(0.005, 0.03) * np.sin(2 * np.pi * rng.uniform(1.5, 4.0) * tt)
            seg[: int(0.3 * fs)] = np.linspace(x, lvl, int(0.3 * fs))[: min(L, int(0.3 * fs))]
        target[i:i + L] = seg
        x = seg[-1]
        i += L
    target = np.clip(target, -stroke, stroke)
    # rate limit (1.5 rad/s at the flap) then a critically damped 2nd-order filter (3 Hz)
    out = np.empty(n)
    y, vy, pos = 0.0, 0.0, 0.0
    w0, dt, vmax = 2 * np.pi * 3.0, 1.0 / fs, 1.5
    for j in range(n):
        pos += float(np.clip(target[j] - pos, -vmax * dt, vmax * dt))
        acc = w0 * w0 * (pos - y) - 2 * w0 * vy
        vy += acc * dt
        y += vy * dt
        out[j] = y
    return np.clip(out, -stroke, stroke)


def temperature_profile(duration: float, fs: float, rng: np.random.Generator) -> np.ndarray:
    """Gearbox temperature (degC): starts at a random ambient, warms up by 15-30 K over the mission."""
    t = np.arange(int(round(duration * fs))) / fs
    T0, dT = rng.uniform(-10.0, 30.0), rng.uniform(15.0, 30.0)
    return T0 + dT * (1.0 - np.exp(-t / (0.4 * duration)))


def gust(duration: float, fs: float, rng: np.random.Generator, rms: float) -> np.ndarray:
    """Band-limited (about 0.1-5 Hz) random torque on the flap."""
    n = int(round(duration * fs))
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    spec[(f < 0.1) | (f > 5.0)] = 0.0
    g = np.fft.irfft(spec, n)
    s = float(np.std(g))
    return g * (rms / s) if s > 0 else g


# ---------------------------------------------------------------------------------------------
# simulation
# ---------------------------------------------------------------------------------------------

def _stack(dicts: list[dict], key: str) -> np.ndarray:
    return np.array([float(d[key]) for d in dicts])


def simulate(missions: list[dict], duration: float = DEFAULT_DURATION, sample_rate: float = DEFAULT_SAMPLE_RATE,
             internal_rate: float = DEFAULT_INTERNAL_RATE) -> list[dict]:
    """Simulate a batch of missions of equal duration; returns one dict of sampled signals per mission.

    Each mission dict: ``seed`` (int), optional ``effect`` (name or override dict), ``plant`` (overrides
    of BASE), ``wear`` (wear depth in m, constant over the mission). Returned dict: ``t``, recorded
    ``theta_m, theta_f, omega_m, omega_f, tau_m, Q_red, theta_ref``, ``t_temp``, ``temperature`` and
    the truth ``truth`` (true Q, i_q, twist, exposure = integral of |Q| |omega_f| dt, parameters).
    """
    B = len(missions)
    fs = float(sample_rate)
    dec = max(1, int(math.ceil(internal_rate / fs - 1e-9)))
    dt = 1.0 / (fs * dec)
    n = int(round(duration * fs))
    P = [dict(BASE, **m.get("plant", {})) for m in missions]
    E = [effect_params(m.get("effect", "clean")) for m in missions]
    rngs = [np.random.default_rng(int(m["seed"])) for m in missions]
    ref = np.stack([reference(duration, fs, r) for r in rngs], 1)
    dref = np.gradient(ref, 1.0 / fs, axis=0)
    temp = np.stack([temperature_profile(duration, fs, r) for r in rngs], 1)
    gst = np.stack([gust(duration, fs, r, p["gust_rms"]) for r, p in zip(rngs, P)], 1)

    g = lambda k: _stack(P, k)  # noqa: E731
    e = lambda k: _stack(E, k)  # noqa: E731
    N, kt, Jm, Jf = g("N"), g("k_t"), g("J_m"), g("J_f")
    Ka, ca, k3, ct = g("K_aero"), g("c_aero"), g("k3"), g("c_t")
    vt, imax, wmax = g("v_t"), g("i_max"), g("omega_max")
    wear = np.array([float(m.get("wear", 0.0)) for m in missions]) / WEAR["d_ref"]
    Fc = g("F_c") * (1.0 + WEAR["friction_gain"] * wear)
    k1 = g("k1") * (1.0 - WEAR["stiffness_loss"] * wear)
    bdz = e("dead_zone") + WEAR["lost_motion_gain"] * wear
    visc = g("b_ref")[None, :] * np.exp(-e("visc_temp_coeff")[None, :] * (temp - g("T_ref")[None, :]))
    A_r, ph_r = e("ripple_amp"), e("ripple_phase")
    F_s, v_s = e("stribeck_rise"), e("stribeck_speed")
    mu_L = e("load_friction")
    A_o, n_o, ph_o = e("out_amp"), e("out_order"), e("out_phase")
    eps_k, ph_k = e("stiff_mod"), e("stiff_phase")
    use_r, use_s, use_o = bool(np.any(A_r)), bool(np.any(F_s)), bool(np.any(A_o))
    use_dz, use_k, use_l = bool(np.any(bdz)), bool(np.any(eps_k)), bool(np.any(mu_L))
    qm = 2 * np.pi / 2.0 ** g("enc_m_bits")
    qf = 2 * np.pi / 2.0 ** g("enc_f_bits")
    Jtot = Jm + Jf / N ** 2
    Kp_w = Jtot * g("wc_w")
    Ki_w = Kp_w * g("wc_w") / 5.0
    Kp_x = g("Kp_x")
    a_i = 1.0 - np.exp(-dt / g("tau_i"))
    a_w = dt / (g("tau_w") + dt)

    # constants folded once (the loop below is the cost: one numpy op per line item, per step)
    inv_qm, inv_qf, invN, inv_vt = 1.0 / qm, 1.0 / qf, 1.0 / N, 1.0 / vt
    c_w, a_wdt = 1.0 - a_w, a_w / dt
    Kix, Kp_kt, inv_kt = Ki_w * dt, Kp_w / kt, 1.0 / kt
    dtJm, dtJf, NKp = dt / Jm, dt / Jf, N * Kp_x
    thm, thf, wm, wf = np.zeros(B), np.zeros(B), np.zeros(B), np.zeros(B)
    iq, integ, wm_est, thm_q_prev = np.zeros(B), np.zeros(B), np.zeros(B), np.zeros(B)
    rec = {k: np.empty((n, B)) for k in ("thm_q", "thf_q", "wm_est", "wm", "wf", "iq", "Q", "twist")}
    iq_all, Q_all = np.empty((n * dec, B)), np.empty((n * dec, B))  # every step: the sensors average these
    for j in range(n):
        thr_c = NKp * ref[j] + N * dref[j]
        bv, Tg = visc[j], gst[j]
        for s in range(dec):
            thm_q = np.rint(thm * inv_qm) * qm  # encoders (counts)
            thf_q = np.rint(thf * inv_qf) * qf
            wm_est = c_w * wm_est + a_wdt * (thm_q - thm_q_prev)  # drive's speed estimate
            thm_q_prev = thm_q
            w_ref = np.minimum(np.maximum(thr_c - NKp * thf_q, -wmax), wmax)  # position loop (P + feed-forward)
            e_w = w_ref - wm_est
            integ_new = integ + Kix * e_w  # speed loop (PI, conditional integration)
            i_un = Kp_kt * e_w + integ_new * inv_kt
            i_ref = np.minimum(np.maximum(i_un, -imax), imax)
            integ = np.where(i_un == i_ref, integ_new, integ)
            iq += a_i * (i_ref - iq)  # current loop: first-order lag, exact step
            w = thm * invN - thf
            wd = wm * invN - wf
            if use_dz:
                we = w - np.minimum(np.maximum(w, -bdz), bdz)
                wd = np.where(we != 0.0, wd, 0.0)
            else:
                we = w
            k1e = k1 * (1.0 + eps_k * np.cos(2.0 * thm + ph_k)) if use_k else k1
            Q = (k1e + k3 * we * we) * we + ct * wd
            iq_all[j * dec + s], Q_all[j * dec + s] = iq, Q
            if s == 0:
                rec["thm_q"][j], rec["thf_q"][j], rec["wm_est"][j] = thm_q, thf_q, wm_est
                rec["wm"][j], rec["wf"][j], rec["iq"][j], rec["Q"][j], rec["twist"][j] = wm, wf, iq, Q, w
            mag = Fc
            if use_s:
                mag = mag + F_s * np.exp(-np.square(wm / v_s))
            if use_l:
                mag = mag + mu_L * np.abs(Q) * invN
            Tm = kt * iq - mag * np.tanh(wm * inv_vt) - bv * wm - Q * invN
            if use_r:
                Tm += A_r * np.cos(2.0 * thm + ph_r)
            if use_o:
                Tm -= A_o * np.sin(n_o * thf + ph_o) * invN
            wm = wm + dtJm * Tm
            wf = wf + dtJf * (Q - Ka * thf - ca * wf - Tg)
            thm = thm + dt * wm
            thf = thf + dt * wf
    # current and torque sensors: mean over the sample period centred on the sample instant (the drive
    # oversamples and averages; instantaneous samples would alias the speed-loop chatter)
    if dec > 1:
        h = dec // 2
        pad = lambda x: np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], dec - h, 0)])  # noqa: E731
        iq_mean = pad(iq_all)[: n * dec].reshape(n, dec, B).mean(1)
        Q_mean = pad(Q_all)[: n * dec].reshape(n, dec, B).mean(1)
    else:
        iq_mean, Q_mean = rec["iq"], rec["Q"]
    # output-side speed estimate of the drive, at the sample rate (filtered difference of the encoder)
    a_f = (1.0 / fs) / (g("tau_w") + 1.0 / fs)
    d_f = np.diff(rec["thf_q"], axis=0, prepend=rec["thf_q"][:1]) * fs
    wf_est = np.stack([lfilter([a_f[b]], [1.0, a_f[b] - 1.0], d_f[:, b]) for b in range(B)], 1)
    exposure = np.sum(np.abs(rec["Q"] * rec["wf"]), 0) / fs  # integral |Q omega_f| dt: load x sliding
    out = []
    for b, m in enumerate(missions):
        r = np.random.default_rng([int(m["seed"]), 7])
        p = P[b]
        i_meas = iq_mean[:, b] + p["i_noise"] * r.standard_normal(n)
        i_meas = np.round(i_meas / p["i_lsb"]) * p["i_lsb"]
        Qm = Q_mean[:, b] + p["Q_noise"] * r.standard_normal(n)
        Qm = np.round(Qm / p["Q_lsb"]) * p["Q_lsb"]
        nT = int(duration * p["temp_rate"])
        idx = np.minimum((np.arange(nT) / p["temp_rate"] * fs).astype(int), n - 1)
        Tm_ = temp[idx, b] + p["temp_noise"] * r.standard_normal(nT)
        out.append({
            "t": np.arange(n) / fs,
            "theta_m": rec["thm_q"][:, b], "theta_f": rec["thf_q"][:, b],
            "omega_m": rec["wm_est"][:, b], "omega_f": wf_est[:, b],
            "tau_m": p["k_t"] * i_meas, "Q_red": Qm, "theta_ref": ref[:, b],
            "t_temp": idx / fs, "temperature": np.round(Tm_ / p["temp_lsb"]) * p["temp_lsb"],
            "truth": {"Q": rec["Q"][:, b], "i_q": rec["iq"][:, b], "twist": rec["twist"][:, b],
                      "omega_m": rec["wm"][:, b], "omega_f": rec["wf"][:, b],
                      "temperature": temp[:, b], "exposure": float(exposure[b]),
                      "plant": p, "effect": E[b], "wear": float(m.get("wear", 0.0)),
                      "dead_zone_total": float(bdz[b]), "k1_eff": float(k1[b]), "F_c_eff": float(Fc[b])},
        })
    return out


# ---------------------------------------------------------------------------------------------
# bag writing (mcap-ros2-support, as any outside tool would)
# ---------------------------------------------------------------------------------------------

_SEP = "=" * 80 + "\n"
_TIME = _SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = _SEP + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
MSGDEF_JOINT_STATE = ("std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
                      "float64[] effort\n" + _HEADER + _TIME)
MSGDEF_TEMPERATURE = "std_msgs/Header header\n\nfloat64 temperature\nfloat64 variance\n" + _HEADER + _TIME
_INF = "    sec: 9223372036\n    nsec: 854775807\n"
QOS = ("- history: unknown\n  depth: 0\n  reliability: reliable\n  durability: volatile\n  deadline:\n" + _INF
       + "  lifespan:\n" + _INF + "  liveliness: automatic\n  liveliness_lease_duration:\n" + _INF
       + "  avoid_ros_namespace_conventions: false")


def write_bag(path: str | os.PathLike, sig: dict, *, actuator_id: str = "EMA2-0001", mission_index: int = 0,
              operating_hours: float = 0.0, start_ns: int = 1_700_000_000_000_000_000,
              extra: dict | None = None) -> Path:
    """Write one mission as a contract bag (MCAP, ROS 2 profile) with mcap-ros2-support."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    p = sig["truth"]["plant"]
    meta = {"contract": "1", "actuator_id": str(actuator_id), "mission_index": str(int(mission_index)),
            "operating_hours": f"{float(operating_hours):.6g}", "gear_ratio": f"{p['N']:g}",
            "torque_constant": f"{p['k_t']:g}", "source": "simulation", "generator": "tests.plants.ema2"}
    meta.update({k: str(v) for k, v in (extra or {}).items()})
    stamps = start_ns + np.round(sig["t"] * 1e9).astype(np.int64)
    t_stamps = start_ns + np.round(sig["t_temp"] * 1e9).astype(np.int64)
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        s_js = w.register_msgdef("sensor_msgs/msg/JointState", MSGDEF_JOINT_STATE)
        s_t = w.register_msgdef("sensor_msgs/msg/Temperature", MSGDEF_TEMPERATURE)
        # mcap-ros2-support registers channels without metadata; register them ourselves first so
        # that every channel carries offered_qos_profiles, as `ros2 bag record` writes it.
        for topic, sch in (("/hd/joint_states", s_js), ("/hd/command", s_js), ("/hd/temperature", s_t)):
            w._channel_ids[topic] = w._writer.register_channel(topic=topic, message_encoding="cdr",
                                                                schema_id=sch.id,
                                                                metadata={"offered_qos_profiles": QOS})
        w.add_metadata("hd_mission", meta)
        _write_rows(w, "/hd/joint_states", s_js, {"name": ["motor", "output"], "position": [0.0, 0.0],
                    "velocity": [0.0, 0.0], "effort": [0.0, 0.0]}, "",
                    stamps, [sig["theta_m"], sig["theta_f"], sig["omega_m"], sig["omega_f"], sig["tau_m"],
                             sig["Q_red"]])
        _write_rows(w, "/hd/command", s_js, {"name": ["output"], "position": [0.0], "velocity": [], "effort": []},
                    "", stamps, [sig["theta_ref"]])
        _write_rows(w, "/hd/temperature", s_t, {"temperature": 0.0, "variance": 0.0025}, "gearbox", t_stamps,
                    [sig["temperature"]])
        w.finish()
    return path


def _write_rows(w, topic: str, schema, template: dict, frame_id: str, stamps: np.ndarray, columns: list) -> None:
    """Encode one message with mcap-ros2-support, then stamp the same fixed layout for every sample.

    All messages on a topic have the same layout (same names, same array lengths), so the CDR bytes of
    sample k are the template's with the stamp and the float64 values replaced; the offsets are found by
    encoding the template with distinct marker values (no hand-written CDR rules).
    """
    from mcap_ros2._dynamic import serialize_dynamic

    enc = serialize_dynamic(schema.name, schema.data.decode())[schema.name]
    msg = copy.deepcopy(template)
    markers = [1000.0 + 0.125 * i for i in range(len(columns))]
    it = iter(markers)
    for key in ("position", "velocity", "effort"):
        if key in msg:
            msg[key] = [next(it) for _ in msg[key]]
    if "temperature" in msg:
        msg["temperature"] = next(it)
    msg["header"] = {"stamp": {"sec": 0x5A5A5A5A, "nanosec": 0x3C3C3C3C}, "frame_id": frame_id}
    tpl = np.frombuffer(enc(msg), np.uint8)
    raw = tpl.tobytes()

    def find(b: bytes) -> int:
        k = raw.find(b)
        if k < 0 or raw.find(b, k + 1) >= 0:
            raise RuntimeError(f"ema2: cannot locate a field in the {schema.name} template")
        return k

    off_sec = find(np.int32(0x5A5A5A5A).tobytes())
    off_ns = find(np.uint32(0x3C3C3C3C).tobytes())
    offs = [find(np.float64(mk).tobytes()) for mk in markers]
    n = len(stamps)
    rows = np.tile(tpl, (n, 1))
    rows[:, off_sec:off_sec + 4] = (stamps // 10**9).astype("<i4").view(np.uint8).reshape(n, 4)
    rows[:, off_ns:off_ns + 4] = (stamps % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    for o, col in zip(offs, columns):
        rows[:, o:o + 8] = np.ascontiguousarray(col, dtype="<f8").view(np.uint8).reshape(n, 8)
    cid = w._channel_ids[topic]
    for k, (st, row) in enumerate(zip(stamps.tolist(), rows)):
        w._writer.add_message(channel_id=cid, log_time=st, publish_time=st, sequence=k, data=row.tobytes())


def _jsonable(o):
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return o


# ---------------------------------------------------------------------------------------------
# case bags (one effect, several missions) and run-to-failure fleets
# ---------------------------------------------------------------------------------------------

CASE_DURATION = 8.0  # s per mission in the test cases (README: why this is enough)
CASE_MISSIONS = 4  # three to fit, the last held out


def simulate_cases(effects=None, missions: int = CASE_MISSIONS, duration: float = CASE_DURATION, seed: int = 0,
                   sample_rate: float = DEFAULT_SAMPLE_RATE, plant: dict | None = None,
                   params: dict | None = None) -> dict:
    """All cases in one batch: {effect: [signals of mission 0..missions-1]}; every case flies the same
    missions (seeds ``seed * 100 + i``), so cases differ only by their effect."""
    effects = list(EFFECTS) if effects is None else list(effects)
    ms = [{"seed": seed * 100 + i, "effect": effect_spec(e, params), "plant": plant or {}}
          for e in effects for i in range(missions)]
    sigs = simulate(ms, duration=duration, sample_rate=sample_rate)
    return {e: sigs[k * missions:(k + 1) * missions] for k, e in enumerate(effects)}


def write_case(out_dir: str | os.PathLike, effect: str = "clean", missions: int = CASE_MISSIONS,
               duration: float = CASE_DURATION, seed: int = 0, sample_rate: float = DEFAULT_SAMPLE_RATE,
               plant: dict | None = None, sigs: list | None = None, params: dict | None = None) -> dict:
    """``missions`` bags of one unit with one effect; returns {bags, fit, held_out, truth, truth_path}.

    ``sigs``: signals from :func:`simulate_cases` (else simulated here). Bags are named
    ``<effect>/mission_<i>.mcap``; the effect name is in the folder and the truth JSON, never in a bag.
    """
    out_dir = Path(out_dir)
    if sigs is None:
        sigs = simulate_cases([effect], missions, duration, seed, sample_rate, plant, params)[effect]
    bags = []
    for i, s in enumerate(sigs):
        bags.append(write_bag(out_dir / f"mission_{i:02d}.mcap", s, actuator_id=f"EMA2-C{seed:03d}",
                              mission_index=i, operating_hours=i * duration / 3600.0,
                              start_ns=1_700_000_000_000_000_000 + i * 3600 * 10**9,
                              extra={"seed": seed * 100 + i, "profile": "ema2_mixed"}))
    spec = effect_spec(effect, params)
    truth = {"plant": "tests.plants.ema2", "effect": effect, "effect_params": effect_params(spec),
             "changed": spec, "signal": EFFECT_SIGNAL[effect], "duration": duration,
             "sample_rate": sample_rate, "bags": [b.name for b in bags], "fit": [b.name for b in bags[:-1]],
             "held_out": bags[-1].name, "base": dict(BASE, **(plant or {}))}
    tp = out_dir / "truth.json"
    tp.write_text(json.dumps(_jsonable(truth), indent=1))
    return {"bags": bags, "fit": bags[:-1], "held_out": bags[-1], "truth": truth, "truth_path": tp,
            "signals": sigs}


def fleet(out_dir: str | os.PathLike, units: int = 6, missions: int = 30, duration: float = 20.0, seed: int = 0,
          life_missions: float = 15.0, effect: str = "clean", hours_per_mission: float = 100.0,
          sample_rate: float = DEFAULT_SAMPLE_RATE, inspect_every: int = 0, params: dict | None = None,
          plant: dict | None = None, remove_frac: float = 0.0) -> dict:
    """Run ``units`` actuators mission by mission until failure (or ``missions``); write bags and truth.

    Wear grows with the transmitted load x sliding of each mission (exposure = integral |Q omega_f| dt),
    at a unit-specific rate, accelerating with wear; a unit fails when its wear reaches its own threshold
    and is found failed at the start of the next mission (it flew the missions before). Layout::

        out_dir/EMA2-U00/mission_000.mcap ...   (only the missions flown)
        out_dir/events.csv                     actuator_id,mission_index,event,quantity,value
        out_dir/fleet_truth.json               wear per mission, thresholds, failure mission, effect

    ``remove_frac``: that fraction of units (drawn) is removed healthy at a planned mission (event
    ``removal``, censored) unless it failed before. Truth never goes into the bags.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([seed, 12345])
    W = WEAR
    # nominal rate so that a unit of rate factor 1 flying nominal missions reaches d_ref after life_missions:
    # dd/dm = a (1 + accel d / d_ref)  ->  m_fail = ln(1 + accel) d_ref / (accel a)
    a_nom = math.log(1.0 + W["accel"]) * W["d_ref"] / (W["accel"] * life_missions)
    E_ref = W["E_ref_per_s"] * duration
    ids = [f"EMA2-U{u:02d}" for u in range(units)]
    rate = np.exp(W["rate_scatter"] * rng.standard_normal(units))
    thr = W["d_ref"] * np.exp(W["threshold_scatter"] * rng.standard_normal(units))
    base = dict(BASE, **(plant or {}))
    unit_plant = [dict(plant or {}, k1=base["k1"] * float(np.exp(0.05 * rng.standard_normal())),
                       F_c=base["F_c"] * float(np.exp(0.1 * rng.standard_normal()))) for _ in range(units)]
    spec = effect_spec(effect, params)
    wear = np.zeros(units)
    hist = {i: [] for i in ids}
    failed = {}
    events = []
    # planned removals (still healthy when removed: censored), drawn before anything is flown
    rr = np.random.default_rng([seed, 777])
    removal_at = {u: int(rr.integers(1, max(2, int(1.2 * life_missions)) + 1)) for u in range(units)
                  if rr.random() < remove_frac}
    removed = {}
    for m in range(missions + 1):  # the check at index `missions` finds units that failed in the last one
        alive = [u for u in range(units) if ids[u] not in failed and ids[u] not in removed]
        for u in list(alive):
            if wear[u] >= thr[u]:
                failed[ids[u]] = m
                events.append((ids[u], m, "failure", "", ""))
                alive.remove(u)
            elif removal_at.get(u) == m:
                removed[ids[u]] = m
                events.append((ids[u], m, "removal", "", ""))
                alive.remove(u)
        if not alive or m == missions:
            break
        ms = [{"seed": seed * 100000 + u * 1000 + m, "effect": spec, "plant": unit_plant[u], "wear": wear[u]}
              for u in alive]
        sigs = simulate(ms, duration=duration, sample_rate=sample_rate)
        for u, s in zip(alive, sigs):
            write_bag(out_dir / ids[u] / f"mission_{m:03d}.mcap", s, actuator_id=ids[u], mission_index=m,
                      operating_hours=m * hours_per_mission,
                      start_ns=1_700_000_000_000_000_000 + m * 86_400 * 10**9,
                      extra={"seed": ms[alive.index(u)]["seed"], "profile": "ema2_mixed"})
            tr = s["truth"]
            inc = a_nom * rate[u] * (tr["exposure"] / E_ref) * (1.0 + W["accel"] * wear[u] / W["d_ref"])
            hist[ids[u]].append({"mission_index": m, "wear_start": float(wear[u]), "wear_end": float(wear[u] + inc),
                                 "exposure": tr["exposure"], "operating_hours": m * hours_per_mission,
                                 "lost_motion": 2 * tr["dead_zone_total"], "k1": tr["k1_eff"], "F_c": tr["F_c_eff"]})
            if inspect_every and m > 0 and m % inspect_every == 0:
                r = np.random.default_rng([seed, u, m, 99])
                events.append((ids[u], m, "inspection", "lost_motion",
                               f"{2 * tr['dead_zone_total'] + 1e-5 * r.standard_normal():.6g}"))
                events.append((ids[u], m, "inspection", "torsional_stiffness",
                               f"{tr['k1_eff'] * (1 + 0.02 * r.standard_normal()):.6g}"))
            wear[u] += inc
    with open(out_dir / "events.csv", "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["actuator_id", "mission_index", "event", "quantity", "value"])
        for row in sorted(events, key=lambda r: (r[0], r[1], r[2])):
            wr.writerow(row)
    truth = {"plant": "tests.plants.ema2", "effect": effect, "effect_params": effect_params(spec),
             "duration": duration, "sample_rate": sample_rate, "hours_per_mission": hours_per_mission,
             "life_missions_nominal": life_missions, "wear_law": W, "a_nom": a_nom,
             "units": [{"actuator_id": ids[u], "rate_factor": float(rate[u]), "threshold": float(thr[u]),
                        "plant": unit_plant[u], "failure_mission": failed.get(ids[u]),
                        "removal_mission": removed.get(ids[u]),
                        "missions": hist[ids[u]]} for u in range(units)]}
    (out_dir / "fleet_truth.json").write_text(json.dumps(_jsonable(truth), indent=1))
    return truth


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------

def _kv(items: list[str], known: dict, what: str) -> dict:
    out = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        if not sep or k not in known:
            raise SystemExit(f"ema2: bad {what} {it!r}: use KEY=VALUE with KEY one of {', '.join(known)}")
        out[k] = float(v)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.plants.ema2", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)

    def common(q, duration):
        q.add_argument("--effect", default="clean", choices=list(EFFECTS))
        q.add_argument("--out", required=True)
        q.add_argument("--duration", type=float, default=duration, help=f"s per mission (default {duration:g})")
        q.add_argument("--seed", type=int, default=0)
        q.add_argument("--rate", type=float, default=DEFAULT_SAMPLE_RATE, help="sample rate, Hz (default 1000)")
        q.add_argument("--gear-ratio", type=float, default=BASE["N"])
        q.add_argument("--param", action="append", metavar="KEY=VALUE",
                       help="override an effect parameter (repeatable), e.g. ripple_amp=0.02")
        q.add_argument("--plant", action="append", metavar="KEY=VALUE",
                       help="override a base-plant parameter (repeatable), e.g. v_t=0.5")

    p = sub.add_parser("mission", help="one mission bag")
    common(p, DEFAULT_DURATION)
    p.add_argument("--wear-um", type=float, default=0.0)
    p.add_argument("--truth", help="also write the truth JSON here")
    c = sub.add_parser("case", help="several missions of one effect (fit + held-out) into a folder")
    common(c, DEFAULT_DURATION)
    c.add_argument("--missions", type=int, default=CASE_MISSIONS)
    f = sub.add_parser("fleet", help="run-to-failure fleet: bags, events.csv, fleet_truth.json")
    common(f, 20.0)
    f.add_argument("--units", type=int, default=6)
    f.add_argument("--missions", type=int, default=30, help="most missions per unit")
    f.add_argument("--life", type=float, default=15.0, help="nominal missions to failure")
    f.add_argument("--hours-per-mission", type=float, default=100.0)
    f.add_argument("--inspect-every", type=int, default=0, help="inspection rows every K missions (0: none)")
    f.add_argument("--remove-frac", type=float, default=0.0,
                   help="fraction of units removed healthy at a planned mission (censored)")
    sub.add_parser("effects", help="list the effects and their parameters")
    a = ap.parse_args(argv)
    t0 = time.time()
    if a.cmd == "effects":
        for k, v in EFFECTS.items():
            print(f"{k:24s} {EFFECT_SIGNAL[k] or '-':6s} {json.dumps(v)}")
        return 0
    params = _kv(a.param, EFFECT_PARAMS0, "--param")
    plant = dict(_kv(a.plant, BASE, "--plant"), N=a.gear_ratio)
    if a.cmd == "mission":
        spec = effect_spec(a.effect, params)
        s = simulate([{"seed": a.seed, "effect": spec, "plant": plant, "wear": a.wear_um * 1e-6}],
                     duration=a.duration, sample_rate=a.rate)[0]
        write_bag(a.out, s, actuator_id="EMA2-0001", extra={"seed": a.seed})
        if a.truth:
            tr = {k: v for k, v in s["truth"].items() if not isinstance(v, np.ndarray)}
            Path(a.truth).write_text(json.dumps(_jsonable(dict(tr, effect_name=a.effect)), indent=1))
        print(f"wrote {a.out} ({a.duration:g} s, effect {a.effect}) in {time.time() - t0:.1f} s")
    elif a.cmd == "case":
        r = write_case(a.out, a.effect, a.missions, a.duration, a.seed, a.rate, plant=plant, params=params)
        print(f"wrote {len(r['bags'])} bags + {r['truth_path']} in {time.time() - t0:.1f} s")
    else:
        tr = fleet(a.out, a.units, a.missions, a.duration, a.seed, a.life, a.effect, a.hours_per_mission,
                   a.rate, a.inspect_every, params=params, plant=plant, remove_frac=a.remove_frac)
        fm = [u["failure_mission"] for u in tr["units"]]
        print(f"wrote fleet to {a.out}: failure missions {fm} in {time.time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
