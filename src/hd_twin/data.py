"""From missions to training tensors: inputs, features, pre-processing, split.

Shared by training, evaluation and the streaming runtime, so batch and node
build the twin's input identically.

* :func:`mission_inputs` -- the raw input matrix ``X[n, 7]`` in SI from a
  :class:`hd_bag.mission.Mission`: columns :data:`RAW_INPUTS` (theta_m rad,
  omega_m rad/s, tau_m N*m, theta_f rad, omega_f rad/s, temperature degC,
  theta_ref rad).
* :func:`features` -- the network's features from ``X`` (model rate). Angles are not fed
  raw (an unwrapped theta_m never repeats, so a network cannot generalise on
  it). We feed instead: the output-side twist ``phi = theta_f - theta_m/N``
  (computed in float64, before any float32 cast: it is the small difference of
  two large numbers), ``sin/cos(theta_m)`` and ``sin/cos(2 theta_m)`` (the WG
  orders where kinematic error, cogging and periodic friction live), theta_f
  itself (a flap angle is bounded), the tracking error ``theta_ref -
  theta_f``, the speeds, tau_m, the temperature, and causal backward-difference
  accelerations of omega_m and omega_f (the inertia torques J theta'' are a
  large part of Q_red in fast manoeuvres), and the odd powers ``phi |phi|``
  [rad^2] and ``phi^3`` [rad^3] of the twist: with them the linear skip path
  represents a hardening torsion law (the catalogue K1/K2/K3 curve, or
  k1 phi + k3 phi^3, PHYSICS.md 2.1) exactly, instead of leaving an S-shaped
  bias for the LSTM to learn. Likewise the friction shapes: ``sgn(omega_m)``
  (regularised, tanh(omega_m / OMEGA_EPS); Coulomb friction of the wave
  generator, N T_C at the output) and ``|tau_m| sgn(omega_m)`` [N*m] (the
  load-dependent meshing loss: efficiency below 1 in driving, above in
  back-driving, PHYSICS.md 2.5), both linear in those features. All features are causal, so the
  streaming runtime computes them sample by sample (carrying one previous row).
* Pre-processing (:func:`preprocess`): optional anti-alias filter (causal
  Butterworth, second-order sections, applied identically in batch and
  streaming) and decimation to the model rate ``fs_model``; NaN samples are
  bridged for the network input only (linear within a segment) and masked out
  of every loss term.
* Differentiation scheme (:func:`derivative`), for the physics residuals only:
  per segment, zero-phase 2nd-order Butterworth low-pass (``cutoff`` Hz, by
  default 0.25 fs) then second-order central differences (``np.gradient``).
  theta_m'' is the derivative of the measured omega_m, theta_f'' of omega_f.
* Split (:func:`split_missions`): by actuator (75/25) when there are >= 2
  actuators, otherwise by mission; never by samples.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from scipy import signal as sps

RAW_INPUTS = ("theta_m", "omega_m", "tau_m", "theta_f", "omega_f", "temperature", "theta_ref")
FEATURES = (
    "phi",
    "sin_theta_m",
    "cos_theta_m",
    "sin_2theta_m",
    "cos_2theta_m",
    "omega_m",
    "omega_f",
    "tau_m",
    "theta_f",
    "e_ref",
    "temperature",
    "alpha_m_bd",
    "alpha_f_bd",
    "phi_abs_phi",
    "phi_cubed",
    "sgn_omega_m",
    "abs_tau_sgn_omega_m",
)
#: Width [rad/s] of the regularised sign tanh(omega_m / OMEGA_EPS) of the friction features.
OMEGA_EPS = 0.05
#: The 13 features of hd_twin/1 models trained before the torsion-law features
#: existed; such models keep working (the feature list is stored in config.json).
FEATURES_V1 = FEATURES[:13]
#: Network outputs: Q_red [N*m], u = x_FS - r_b theta_m [m], y_FS [m].
OUTPUTS = ("Q_red", "u_FS", "y_FS")


def mission_inputs(mission) -> np.ndarray:
    """Raw twin input matrix ``X[n, 7]`` (float64, SI) of a Mission, columns :data:`RAW_INPUTS`.

    Temperature is the gearbox frame (the motor winding when no gearbox
    sensor exists; NaN when the bag has none); theta_ref is held onto the
    joint-state stamps (zero-order hold).
    """
    n = mission.n
    cols = [
        mission.theta_m,
        mission.omega_m,
        mission.tau_m,
        mission.theta_f,
        mission.omega_f,
        mission.temperature_on_t("gearbox"),
        mission.theta_ref_on_t(),
    ]
    X = np.empty((n, len(RAW_INPUTS)), dtype=np.float64)
    for j, c in enumerate(cols):
        c = np.asarray(c, dtype=np.float64)
        if c.shape != (n,):
            raise ValueError(f"{mission.report.path or mission.meta.actuator_id}: input {RAW_INPUTS[j]} has shape {c.shape}, expected ({n},)")
        X[:, j] = c
    return X


def features(X: np.ndarray, N: float, dt: float, prev: np.ndarray | None = None,
             fill: np.ndarray | None = None, names: Sequence[str] | None = None) -> np.ndarray:
    """Network features ``F[n, len(names)]`` (float64) from raw inputs ``X[n, 7]`` at the model rate; see the module docstring.

    ``names`` selects and orders the columns (default :data:`FEATURES`; a
    model's ``config.json["features"]``, so older models keep their set).

    ``dt`` [s] is the model sample period, ``prev`` the raw input row before
    ``X[0]`` (streaming: the last row of the previous block; None at a
    segment start, where the backward differences are zero). ``fill``
    (length ``len(names)``) replaces non-finite feature values (e.g. no temperature
    sensor, no command yet); by default they stay NaN.
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != len(RAW_INPUTS):
        raise ValueError(f"twin input must have shape (n, {len(RAW_INPUTS)}) with columns {RAW_INPUTS}, got {X.shape}")
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"model sample period dt must be a positive number, got {dt!r}")
    th_m, w_m, tau, th_f, w_f, temp, th_ref = X.T
    w_prev = X[:1, [1, 4]] if prev is None else np.asarray(prev, dtype=np.float64)[None, [1, 4]]
    acc = np.diff(np.vstack([w_prev, X[:, [1, 4]]]), axis=0) / dt  # causal backward differences
    phi = th_f - th_m / N
    sgn_w = np.tanh(w_m / OMEGA_EPS)
    F = np.column_stack(
        [
            phi,
            np.sin(th_m),
            np.cos(th_m),
            np.sin(2 * th_m),
            np.cos(2 * th_m),
            w_m,
            w_f,
            tau,
            th_f,
            th_ref - th_f,
            temp,
            acc[:, 0],
            acc[:, 1],
            phi * np.abs(phi),
            phi**3,
            sgn_w,
            np.abs(tau) * sgn_w,
        ]
    )
    if names is not None and tuple(names) != FEATURES:
        F = F[:, feature_columns(names)]
    if fill is not None:
        bad = ~np.isfinite(F)
        if bad.any():
            F[bad] = np.broadcast_to(np.asarray(fill, dtype=np.float64), F.shape)[bad]
    return F


def feature_columns(names: Sequence[str]) -> list[int]:
    """Column indices of ``names`` in :data:`FEATURES`; ValueError naming an unknown feature."""
    unknown = [n for n in names if n not in FEATURES]
    if unknown:
        raise ValueError(f"unknown twin feature(s) {unknown}; known: {FEATURES}")
    return [FEATURES.index(n) for n in names]


def check_twist_reference(mission, N: float, where: str) -> None:
    """Refuse a mission whose motor and output encoders have no common zero (ValueError naming it).

    The twin's inputs are built on the output-side twist ``phi = theta_f - theta_m / N`` [rad]; an
    encoder offset adds a constant to it that no training covers (a 1e4 rad theta_m offset gave
    R^2 = -2e30 on a foreign bag). Threshold: ``hd_bag.mission.MAX_TWIST_OFFSET``.
    """
    from hd_bag.mission import MAX_TWIST_OFFSET  # noqa: PLC0415

    tw = np.asarray(mission.theta_f, float) - np.asarray(mission.theta_m, float) / N
    tw = tw[np.isfinite(tw)]
    if len(tw) and abs(float(np.median(tw))) > MAX_TWIST_OFFSET:
        raise ValueError(f"{where}: theta_f - theta_m / N has median {float(np.median(tw)):.6g} rad (N = {N:g}), "
                         f"beyond any transmission twist (> {MAX_TWIST_OFFSET:g} rad): motor and output encoders "
                         "have no common zero; co-reference them (theta_m = N theta_f + twist) before using the twin")


def segment_bounds(segment: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the constant runs of ``segment``."""
    seg = np.asarray(segment)
    if len(seg) == 0:
        return []
    cut = np.flatnonzero(np.diff(seg) != 0) + 1
    starts = np.r_[0, cut]
    stops = np.r_[cut, len(seg)]
    return list(zip(starts.tolist(), stops.tolist()))


def bridge_nan(x: np.ndarray) -> np.ndarray:
    """Linear interpolation over NaN samples along axis 0 (edges held); all-NaN columns stay NaN."""
    x = np.array(x, dtype=np.float64, copy=True)
    one = x.ndim == 1
    if one:
        x = x[:, None]
    idx = np.arange(len(x))
    for j in range(x.shape[1]):
        ok = np.isfinite(x[:, j])
        if ok.all() or not ok.any():
            continue
        x[~ok, j] = np.interp(idx[~ok], idx[ok], x[ok, j])
    return x[:, 0] if one else x


def antialias_sos(fs: float, decimation: int, order: int = 4):
    """Causal Butterworth anti-alias filter (SOS) with cut-off 0.8 x the new Nyquist, or None."""
    if decimation <= 1:
        return None
    return sps.butter(order, 0.8 * (fs / decimation / 2.0), fs=fs, output="sos")


#: Half-width [samples] and threshold [robust standard deviations] of :func:`bound_outliers`.
HAMPEL_HALF, HAMPEL_K = 3, 6.0


def bound_outliers(x: np.ndarray, half: int = HAMPEL_HALF, k: float = HAMPEL_K) -> np.ndarray:
    """Hampel bound: a sample farther than ``k`` robust standard deviations from the median of its
    ``2 half + 1`` neighbours is replaced by that median (isolated spikes: encoder glitches, torque
    sensor hits); the scale is 1.4826 x the median absolute deviation of the whole signal from its
    running median, so a smooth signal is never touched. Vectorised (scipy.ndimage)."""
    from scipy.ndimage import median_filter  # noqa: PLC0415

    x = np.asarray(x, dtype=np.float64)
    if len(x) < 2 * half + 2 or not np.isfinite(x).all():
        return x
    med = median_filter(x, size=2 * half + 1, mode="nearest")
    dev = np.abs(x - med)
    s = 1.4826 * float(np.median(dev))
    if not s > 0:
        return x
    bad = dev > k * s
    return np.where(bad, med, x) if bad.any() else x


def derivative(x: np.ndarray, dt: float, cutoff: float | None = None) -> np.ndarray:
    """Time derivative of one segment: outliers bounded (:func:`bound_outliers`), zero-phase low-pass
    (2nd-order Butterworth, designed at the segment's rate) + central differences.

    ``x`` [n] finite, ``dt`` [s], ``cutoff`` [Hz] (default 0.25/dt, None-> no
    filter when the segment is too short for filtfilt).
    """
    x = bound_outliers(np.asarray(x, dtype=np.float64))
    if len(x) < 3:
        return np.zeros_like(x)
    fs = 1.0 / dt
    fc = 0.25 * fs if cutoff is None else float(cutoff)
    if fc < 0.5 * fs and len(x) > 15:
        sos = sps.butter(2, fc, fs=fs, output="sos")
        x = sps.sosfiltfilt(sos, x, padlen=min(len(x) - 1, 12))
    return np.gradient(x, dt, edge_order=2)


def edge_half_window(dt: float, cutoff_hz: float | None = None) -> int:
    """Samples at each end of a segment where the twin's derived signals are not defined: half the window of
    the physics path's derivative filter (:func:`hd_twin.identify.sg_window` at the model rate, -3 dB at
    ``cutoff_hz``, default :data:`hd_twin.identify.DERIV_CUTOFF_HZ`).

    Why: a derivative at a sample needs the signal on both sides over the filter's window; within half a window
    of a segment's start or end the Savitzky-Golay filter extrapolates its edge polynomial fit, which is wrong
    when the motion has a kink there (a mission that starts with a step in acceleration: measured 4263 N*m
    paper-preset maximum error on the first sample of the sweep missions, every other sample within 417 N*m).
    These samples are *edge samples*: excluded from the losses and the error metrics (counted), not predicted
    differently. The streaming twin's counterpart is its window fill after a reset
    (:attr:`hd_twin.runtime.StreamingTwin.edge_s`)."""
    from .identify import DERIV_CUTOFF_HZ, sg_window  # noqa: PLC0415

    return int(sg_window(1.0 / dt, DERIV_CUTOFF_HZ if cutoff_hz is None else cutoff_hz) // 2)


def edge_samples(n: int, dt: float, cutoff_hz: float | None = None) -> np.ndarray:
    """Bool [n]: the first and last :func:`edge_half_window` samples of a segment of ``n`` samples."""
    m = edge_half_window(dt, cutoff_hz)
    e = np.zeros(n, bool)
    e[:m] = True
    e[max(n - m, 0):] = True
    return e


@dataclass
class Segment:
    """One gap-free stretch of one mission at the model rate; arrays [n]."""

    source: str  # bag path or mission label
    actuator_id: str
    mission_index: int
    dt: float  # s, model sample period
    N: float
    k_t: float
    X: np.ndarray  # [n, 7] raw inputs (filtered/decimated, NaN bridged)
    F: np.ndarray  # [n, 13] features (NaN where not computable)
    Q_red: np.ndarray  # [n] measured output torque (NaN where absent)
    mask: np.ndarray  # [n] bool: all raw inputs and Q_red were finite before bridging, and not an edge sample
    theta_m_dd: np.ndarray  # [n] rad/s^2
    theta_f_dd: np.ndarray  # [n] rad/s^2
    phi: np.ndarray  # [n] rad, theta_f - theta_m/N (float64)
    phi_d: np.ndarray  # [n] rad/s
    temperature: np.ndarray  # [n] degC (NaN-bridged; T_ref where absent)
    Q_phys: np.ndarray | None = None  # [n] N*m, the identified physics path (hd_twin.physpath), set by training
    edge: np.ndarray | None = None  # [n] bool: measured samples that are edge samples (:func:`edge_samples`), left out of ``mask``

    @property
    def n(self) -> int:
        return len(self.Q_red)


def decimation_for(fs: float, fs_model: float | None, where: str) -> int:
    """Integer decimation from a bag rate ``fs`` to the model rate; refuses rates that do not fit."""
    if not math.isfinite(fs) or fs <= 0:
        raise ValueError(f"{where}: cannot determine the joint-state sample rate (got {fs})")
    if fs_model is None:
        return 1
    d = max(1, int(round(fs / fs_model)))
    if abs(fs / d - fs_model) > 0.05 * fs_model:
        raise ValueError(
            f"{where}: joint states at {fs:.1f} Hz cannot be decimated to the model rate {fs_model:.1f} Hz "
            f"by an integer factor (nearest gives {fs / d:.1f} Hz)"
        )
    return d


def preprocess(mission, fs_model: float | None = None, T_ref: float = 25.0, min_len: int = 16,
               names: Sequence[str] | None = None, speed_timing=None, twist_smoothing=None) -> list[Segment]:
    """Split a Mission into gap-free, anti-aliased, decimated :class:`Segment` s at ``fs_model`` Hz.

    ``names``: the feature columns of ``Segment.F`` (default :data:`FEATURES`). ``speed_timing``: the
    model's ``config.json:speed_timing`` (dict or :class:`hd_twin.speedtiming.SpeedTiming`; None / empty:
    speeds as logged): the listed logged speeds are re-timed per segment at the bag rate, before anything
    else sees them (the streaming twin does the same causally). ``twist_smoothing``: the model's
    ``config.json:twist_smoothing`` (dict or :class:`hd_twin.twistsmooth.TwistSmoothing`; None / empty: theta_f
    as logged): theta_f smoothed per segment at the bag rate, as discovery fitted the model's Q_red terms.

    Segments shorter than ``min_len`` samples (after decimation) are dropped.
    Raises ValueError naming the bag when the mission is unusable.
    """
    where = mission.report.path or f"{mission.meta.actuator_id}/{mission.meta.mission_index}"
    if mission.n < 3:
        raise ValueError(f"{where}: only {mission.n} joint-state samples")
    N = float(mission.meta.gear_ratio)
    if not math.isfinite(N) or N <= 0:
        raise ValueError(f"{where}: gear_ratio {mission.meta.gear_ratio!r} is not a positive number")
    check_twist_reference(mission, N, where)
    fs = mission.fs
    dec = decimation_for(fs, fs_model, where)
    X_all = mission_inputs(mission)
    Q_all = np.asarray(mission.Q_red, dtype=np.float64)
    finite = np.isfinite(X_all[:, [0, 1, 2, 3, 4]]).all(axis=1) & np.isfinite(Q_all)
    if not finite.any():
        raise ValueError(f"{where}: no sample has all of theta_m, omega_m, tau_m, theta_f, omega_f and Q_red "
                         "finite" + (" (Q_red is NaN throughout: no output torque sensor, so the twin can be "
                                     "neither trained nor scored on this bag)" if not np.isfinite(Q_all).any() else ""))
    sos = antialias_sos(fs, dec)
    from .speedtiming import SpeedTiming  # noqa: PLC0415

    from .twistsmooth import TwistSmoothing  # noqa: PLC0415

    timing = speed_timing if isinstance(speed_timing, SpeedTiming) else SpeedTiming.from_config(speed_timing)
    smoothing = (twist_smoothing if isinstance(twist_smoothing, TwistSmoothing)
                 else TwistSmoothing.from_config(twist_smoothing))
    t_all = np.asarray(mission.t, dtype=np.float64)
    out: list[Segment] = []
    for a, b in segment_bounds(mission.segment):
        if b - a < max(3, min_len * dec):
            continue
        X = bridge_nan(X_all[a:b])
        absent = ~np.isfinite(X).all(axis=0)  # inputs with no finite sample in this segment
        X[:, absent] = 0.0
        X = timing.apply_X(X, t_all[a:b])  # X itself when the model has no re-timing
        X = smoothing.apply_X(X, fs)  # X itself when the model reads theta_f as logged
        Q = Q_all[a:b].copy()
        m = finite[a:b].copy()
        Qb = bridge_nan(Q)
        if sos is not None:
            zi = sps.sosfilt_zi(sos)
            X = np.column_stack([sps.sosfilt(sos, X[:, j], zi=zi * X[0, j])[0] for j in range(X.shape[1])])
            Qb = sps.sosfilt(sos, Qb, zi=zi * Qb[0])[0] if np.isfinite(Qb).all() else Qb
            # a masked sample contaminates the filtered output for ~the filter's memory
            m = np.convolve(~m, np.ones(4 * dec), mode="full")[: len(m)] == 0
            X, Qb, m = X[::dec], Qb[::dec], m[::dec]
            Q = np.where(m, Qb, np.nan)
        else:
            Q = np.where(m, Q, np.nan)
        dt = dec / fs
        edge = edge_samples(len(X), dt)
        phi = X[:, 3] - X[:, 0] / N
        F = features(X, N, dt)
        F[:, 9] = np.nan if absent[6] or absent[3] else F[:, 9]  # no command: feature -> training mean
        F[:, 10] = np.nan if absent[5] else F[:, 10]  # no temperature sensor: feature -> training mean
        if names is not None and tuple(names) != FEATURES:
            F = F[:, feature_columns(names)]
        temp = np.full(len(X), T_ref) if absent[5] else X[:, 5].copy()
        out.append(
            Segment(
                source=where,
                actuator_id=str(mission.meta.actuator_id),
                mission_index=int(mission.meta.mission_index),
                dt=dt,
                N=N,
                k_t=float(mission.meta.torque_constant),
                X=X,
                F=F,
                Q_red=Q,
                mask=m & np.isfinite(Q) & ~edge,
                theta_m_dd=derivative(X[:, 1], dt),
                theta_f_dd=derivative(X[:, 4], dt),
                phi=phi,
                phi_d=derivative(phi, dt),
                temperature=temp,
                edge=edge & m & np.isfinite(Q),
            )
        )
    return out


# ---- normalisation -----------------------------------------------------------
@dataclass
class Normalizer:
    """Feature and Q_red statistics of the training set, stored with the model."""

    f_mean: np.ndarray
    f_std: np.ndarray
    q_mean: float
    q_std: float

    @classmethod
    def fit(cls, segments: Sequence[Segment], names: Sequence[str] = FEATURES) -> "Normalizer":
        F = np.concatenate([s.F for s in segments])
        Q = np.concatenate([s.Q_red[s.mask] for s in segments])
        if len(Q) < 2:
            raise ValueError("training set has fewer than two valid Q_red samples")
        mean = np.nanmean(F, axis=0)
        std = np.nanstd(F, axis=0)
        mean = np.where(np.isfinite(mean), mean, 0.0)
        # relative test: the twist powers are tiny in SI (phi^3 ~ 1e-8 rad^3) but informative
        std = np.where(np.isfinite(std) & (std > 0) & (std > 1e-9 * np.abs(mean)), std, 1.0)
        # sin/cos features keep their natural scale (zero mean, unit amplitude)
        if F.shape[1] != len(names):
            raise ValueError(f"Normalizer.fit: segments have {F.shape[1]} features, names give {len(names)}")
        for j, name in enumerate(names):
            if name.startswith(("sin_", "cos_")):
                mean[j], std[j] = 0.0, 1.0
        q_std = float(np.std(Q))
        return cls(mean, std, float(np.mean(Q)), q_std if q_std > 1e-12 else 1.0)

    def norm_features(self, F: np.ndarray) -> np.ndarray:
        Z = (F - self.f_mean) / self.f_std
        Z[~np.isfinite(Z)] = 0.0  # missing feature -> training mean
        return Z

    def to_dict(self) -> dict:
        return {"f_mean": self.f_mean.tolist(), "f_std": self.f_std.tolist(), "q_mean": self.q_mean, "q_std": self.q_std}

    @classmethod
    def from_dict(cls, d: dict) -> "Normalizer":
        return cls(np.asarray(d["f_mean"], float), np.asarray(d["f_std"], float), float(d["q_mean"]), float(d["q_std"]))


# ---- split -------------------------------------------------------------------
def split_missions(keys: Sequence[tuple[str, str]], val_frac: float = 0.25, seed: int = 0) -> tuple[list[int], list[int]]:
    """Split missions into train / validation indices at actuator level.

    ``keys`` = (actuator_id, mission label) per mission. With >= 2 actuators
    whole actuators go to one side (``round(val_frac * n_actuators)``, at
    least 1, at most n-1); with a single actuator whole missions are split.
    Never splits a mission. Deterministic for a seed.
    """
    if not 0.0 < val_frac < 1.0:
        raise ValueError(f"validation fraction must be in (0, 1), got {val_frac}")
    if len(keys) < 2:
        raise ValueError(f"need at least two missions to split into training and validation, got {len(keys)}")
    rng = np.random.default_rng(seed)
    acts = sorted({a for a, _ in keys})
    if len(acts) >= 2:
        n_val = min(len(acts) - 1, max(1, int(round(val_frac * len(acts)))))
        val_acts = set(rng.permutation(acts)[:n_val].tolist())
        val = [i for i, (a, _) in enumerate(keys) if a in val_acts]
    else:
        labels = sorted({m for _, m in keys})
        n_val = min(len(labels) - 1, max(1, int(round(val_frac * len(labels)))))
        val_lab = set(rng.permutation(labels)[:n_val].tolist())
        val = [i for i, (_, m) in enumerate(keys) if m in val_lab]
    tr = [i for i in range(len(keys)) if i not in set(val)]
    return tr, val


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while b := f.read(chunk):
            h.update(b)
    return h.hexdigest()


def find_bags(paths: Iterable[str | Path]) -> list[Path]:
    """Expand files and directories (recursively) into a sorted list of ``.mcap`` files (repeats dropped);
    ValueError naming a missing path or when there is no bag (:func:`hd_bag.files.find_bags`)."""
    from hd_bag.files import find_bags as find

    return find(paths, unique="sorted")


def windows(seg_lengths: Sequence[int], length: int, stride: int) -> list[tuple[int, int]]:
    """(segment index, start) of every training window of ``length`` samples."""
    out = []
    for i, n in enumerate(seg_lengths):
        if n < length:
            if n >= max(16, length // 4):
                out.append((i, -1))  # a short segment used whole (padded)
            continue
        starts = list(range(0, n - length + 1, stride))
        if starts[-1] != n - length:
            starts.append(n - length)
        out += [(i, s) for s in starts]
    return out
