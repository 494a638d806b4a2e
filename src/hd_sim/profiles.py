"""Mission profiles: commanded flap angle, gust hinge moment and ambient conditions.

A profile is sampled at the log rate ``fs``; the plant holds the command
between samples (as a drive holds the last setpoint) and interpolates the gust.
Kinds: ``step`` (deploy/retract steps), ``ramp``, ``sine``, ``sweep`` (chirp
0.2-2 Hz), ``gust`` (holds under strong gusts), ``flight`` (random flight-like
mix of all), ``inspection`` (the standard manoeuvre every mission starts with:
slow reversal ramp, a deploy/retract step pair and a short sine; then a random
flight segment), ``hold``; and three beyond our flap missions: ``constant_sweep`` (long
constant-speed sweeps across the travel at a slow rate drawn per mission, 1-10 deg/s),
``dither`` (small-stroke dither, +-0.05-0.5 deg at 1-6 Hz around a hold: friction transition
and pre-sliding), ``parked`` (command fixed, the load held against gusts: no motion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from .kernel import rate_limit

PROFILES = ("inspection", "step", "ramp", "sine", "sweep", "gust", "flight", "hold",
            "constant_sweep", "dither", "parked")


@dataclass
class Profile:
    kind: str
    fs: float  # Hz
    theta_ref: np.ndarray  # rad, output command per log sample
    omega_ff: np.ndarray  # rad/s, feed-forward output rate
    gust: np.ndarray  # N*m, external hinge moment before the aero_gusts scale
    T_amb: float  # degC
    q_scale: float = 1.0  # dynamic-pressure factor on K_aero, c_aero
    T_w0: float | None = None  # degC initial winding temperature (None: ambient + warm)
    T_h0: float | None = None
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.theta_ref)


def band_limited_noise(n: int, fs: float, rng: np.random.Generator, f_lo: float = 0.1, f_hi: float = 5.0) -> np.ndarray:
    """Zero-mean, unit-std noise band-limited to [f_lo, f_hi] Hz (4th-order Butterworth, zero-phase)."""
    if n < 8:
        return np.zeros(n)
    w = rng.standard_normal(n + 2000)
    sos = signal.butter(2, [f_lo, min(f_hi, 0.45 * fs)], btype="bandpass", fs=fs, output="sos")
    y = signal.sosfiltfilt(sos, w)[1000:1000 + n]
    s = y.std()
    return y / s if s > 0 else y


def _shape(target: np.ndarray, fs: float, rate: float, acc: float, x0: float) -> tuple[np.ndarray, np.ndarray]:
    pos, vel = rate_limit(np.ascontiguousarray(target, dtype=np.float64), 1.0 / fs, rate, acc, x0)
    # smooth the jerk (2nd-order critically damped, 15 Hz), keep the rate consistent
    sos = signal.butter(2, 15.0, fs=fs, output="sos")
    zi = signal.sosfilt_zi(sos)
    pos = signal.sosfilt(sos, pos, zi=zi * pos[0])[0]
    vel = np.gradient(pos, 1.0 / fs)
    return pos, vel


def make_profile(kind: str, duration: float, fs: float = 1000.0, seed: int = 0, *,
                 amplitude_deg: float | None = None, rate_max_deg: float = 80.0,
                 T_amb: float | None = None, gust_Nm: float | None = None) -> Profile:
    """Build a profile of ``kind`` lasting ``duration`` s at ``fs`` Hz (seeded)."""
    if kind not in PROFILES:
        raise ValueError(f"unknown profile {kind!r}; one of {PROFILES}")
    if not (0.05 <= duration <= 7200.0):
        raise ValueError(f"duration {duration!r} s outside [0.05, 7200]")
    if not (50.0 <= fs <= 20000.0):
        raise ValueError(f"sample rate {fs!r} Hz outside [50, 20000]")
    rng = np.random.default_rng([int(seed), 0xF1A9])
    n = int(round(duration * fs))
    t = np.arange(n) / fs
    deg = math.pi / 180.0
    amp = (amplitude_deg if amplitude_deg is not None else rng.uniform(10.0, 22.0)) * deg
    rate = rate_max_deg * deg
    acc = 6.0 * rate
    x0 = 0.0
    gust_level = gust_Nm if gust_Nm is not None else rng.uniform(60.0, 200.0)
    T_amb = float(T_amb) if T_amb is not None else float(rng.uniform(-30.0, 40.0))
    q_scale = float(rng.uniform(0.6, 1.15))
    info: dict = {}

    def steps(tt, rng_):
        m = len(tt)
        tgt = np.zeros(m)
        k = 0
        while k < m:
            hold = int(rng_.uniform(0.8, 3.0) * fs)
            tgt[k:k + hold] = rng_.uniform(-1.0, 1.0) * amp
            k += hold
        return tgt

    if kind == "hold":
        target = np.full(n, rng.uniform(-0.5, 0.5) * amp)
        pos, vel = _shape(target, fs, rate, acc, target[0])
    elif kind == "step":
        target = np.where((t % 6.0) < 3.0, amp, -0.3 * amp)
        target[t < 0.5] = 0.0
        pos, vel = _shape(target, fs, rate, acc, x0)
    elif kind == "ramp":
        period = 4.0 * amp / (0.25 * rate)
        ph = (t / period) % 1.0
        target = amp * (4.0 * np.abs(ph - 0.5) - 1.0) * -1.0
        pos, vel = _shape(target, fs, rate, acc, target[0])
    elif kind == "sine":
        f = rng.uniform(0.2, 2.0)
        a = min(amp, 0.9 * rate / (2 * math.pi * f))
        pos = a * np.sin(2 * math.pi * f * t)
        vel = a * 2 * math.pi * f * np.cos(2 * math.pi * f * t)
        info["f_Hz"] = f
    elif kind == "sweep":
        f0, f1 = 0.2, 2.0
        T = max(duration, 1e-3)
        k_ = (f1 / f0) ** (1.0 / T)
        phase = 2 * math.pi * f0 * (k_ ** t - 1.0) / math.log(k_)
        finst = f0 * k_ ** t
        a = np.minimum(amp, 0.9 * rate / (2 * math.pi * finst))
        pos = a * np.sin(phase)
        vel = np.gradient(pos, 1.0 / fs)
    elif kind == "constant_sweep":
        v = rng.uniform(1.0, 10.0) * deg  # output rate of the sweep
        period = 4.0 * amp / v
        ph = (t / period + 0.25) % 1.0
        target = amp * (1.0 - 4.0 * np.abs(ph - 0.5))  # triangle through 0 at t = 0, constant |rate| v
        pos, vel = _shape(target, fs, rate, acc, 0.0)
        info["rate_rad_s"] = v
    elif kind == "dither":
        a = rng.uniform(0.05, 0.5) * deg
        f = rng.uniform(1.0, 6.0)
        c = rng.uniform(-0.5, 0.5) * amp
        t1 = np.maximum(t - 0.5, 0.0)  # 0.5 s move to the hold angle, then the dither fades in over 0.5 s
        pos = (c * 0.5 * (1 - np.cos(math.pi * np.minimum(t / 0.5, 1.0)))
               + a * np.minimum(t1 / 0.5, 1.0) * np.sin(2 * math.pi * f * t1))
        vel = np.gradient(pos, 1.0 / fs)
        info.update(dither_amp_rad=a, f_Hz=f)
    elif kind == "parked":
        target = np.full(n, rng.uniform(-0.5, 0.5) * amp)
        pos, vel = target.copy(), np.zeros(n)
        gust_level *= 2.0
    elif kind == "gust":
        target = steps(t, rng) * 0.6
        pos, vel = _shape(target, fs, rate, acc, x0)
        gust_level *= 3.0
    elif kind in ("flight", "inspection"):
        # segments: [kind, seconds]; inspection starts with the standard manoeuvre
        segs: list[tuple[str, float]] = []
        if kind == "inspection":
            segs = [("rest", 0.5), ("rev", 4.0 * amp / (0.25 * rate) * 0.5 + 0.5), ("steps2", 3.0), ("sine1", 2.0)]
        used = sum(s for _, s in segs)
        while used < duration:
            s = (str(rng.choice(["steps", "sine", "ramp", "hold"])), float(rng.uniform(2.0, 6.0)))
            segs.append(s)
            used += s[1]
        target = np.zeros(n)
        direct = np.full(n, np.nan)
        k = 0
        for name, sec in segs:
            m = int(sec * fs)
            if k >= n:
                break
            m = min(m, n - k)
            tt = np.arange(m) / fs
            if name == "rest":
                target[k:k + m] = 0.0
            elif name == "rev":  # slow ramp out and back (lost-motion / friction reversal test)
                v = 0.25 * rate
                half = m // 2
                up = np.minimum(v * tt[:half], 0.8 * amp)
                target[k:k + half] = up
                target[k + half:k + m] = up[-1] - np.minimum(v * tt[: m - half], 1.6 * amp)
            elif name == "steps2":
                target[k:k + m] = np.where(tt < sec / 2, amp, -amp)
            elif name in ("sine1", "sine"):
                f = 1.0 if name == "sine1" else rng.uniform(0.2, 2.0)
                a = min(amp * (0.5 if name == "sine1" else rng.uniform(0.3, 1.0)), 0.8 * rate / (2 * math.pi * f))
                c = target[k - 1] if k else 0.0
                direct[k:k + m] = c + a * np.sin(2 * math.pi * f * tt)
            elif name == "steps":
                target[k:k + m] = steps(tt, rng)
            elif name == "ramp":
                target[k:k + m] = np.linspace(target[k - 1] if k else 0.0, rng.uniform(-1, 1) * amp, m)
            else:  # hold
                target[k:k + m] = target[k - 1] if k else 0.0
            if name not in ("sine1", "sine"):
                direct[k:k + m] = np.nan
            else:
                target[k:k + m] = direct[k:k + m]
            k += m
        pos, vel = _shape(target, fs, rate, 3.0 * acc, 0.0)
        info["segments"] = [s for s, _ in segs]
    else:  # pragma: no cover
        raise AssertionError(kind)
    gust = gust_level * band_limited_noise(n, fs, rng)
    return Profile(kind, fs, np.ascontiguousarray(pos), np.ascontiguousarray(vel), gust, T_amb, q_scale,
                   info=info | {"gust_Nm": gust_level, "amplitude_rad": amp})
