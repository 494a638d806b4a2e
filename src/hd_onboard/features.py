"""Health features of the harmonic drive from the contract signals (no ``/sim`` access).

In-flight feature (``HF_MTW,IF``, paper section 4.1) and its companions come
from the kinematic (transmission) error, PHYSICS.md section 6.1::

    TE = theta_f - theta_m / N - Q / K(Q)

with ``K`` the nominal (catalogue) three-slope stiffness law. TE still holds
the kinematic-error harmonics, lost motion (backlash) and whatever the
nominal law misses. One least-squares fit per block separates them::

    TE ~ c0 + c_Q Q + c_bl sgn(Q) + c_hy sgn(dQ/dt)
         + sum_{k=1,2,4} (a_k sin k theta_m + b_k cos k theta_m)

* ``ke_2x`` = sqrt(a_2^2 + b_2^2) [rad]: the order-tracked 2x wave-generator
  amplitude (regression on theta_m is order tracking that needs no
  resampling and tolerates NaN, gaps and irregular stamps). The in-flight
  feature ``HF_MTW_IF`` is this amplitude by default.
* ``ke_1x``, ``ke_4x`` [rad]; ``ke_kx_s``, ``ke_kx_c`` = a_k, b_k [rad] (the
  phasors, for coherent averaging over windows); ``lost_motion`` = 2 |c_bl| [rad] (the jump of
  the output across a torque reversal); ``hysteresis`` = 2 |c_hy| [rad];
  ``compliance_residual`` = c_Q [rad/(N m)] (what the nominal law misses:
  stiffness loss); ``te_rms`` [rad]: RMS of TE minus its mean and linear
  elastic part.
* Ground ``ke_indicator`` [rad]: RMS of the fitted non-elastic part of TE
  (harmonics + lost motion + hysteresis): the deviation between expected
  and actual output position.
* Ground ``cs_gain`` [A s/rad]: the current-speed gain g of
  ``i_q = a sgn(w) + g w f_T + (J/k_t) w' + c Q + d`` with ``f_T =
  exp(-beta_T (T_h - T_ref))`` (viscous friction follows the lubricant
  viscosity, PHYSICS.md 2.5 and 3.4), so g is the gain at ``T_ref``:
  temperature-compensated. Also ``cs_coulomb`` = |a| [A] (the Coulomb
  friction current, which grows with mesh wear) and ``cs_rms_ratio`` =
  RMS(i_q)/RMS(omega_m).
* ``efficiency`` = sum(Q w_f) / sum(tau_m w_m) over motoring samples.
* ``W_load`` [J]: the Archard load-sliding integral ``int |Q| |omega_m| dt``
  of the block (mean power over the valid samples times the block
  duration, so dropouts do not hide wear).

Without a torque sensor (``Q_red`` all NaN) the reflected motor torque
``Q_hat = N eta_nom tau_m`` stands in for ``Q`` everywhere (the fit's
``c_Q`` absorbs the scale error), and ``torque_source`` says so. Blocks with
too little wave-generator rotation for the harmonics (< ``min_wg_turns``)
give NaN harmonic features and a reason in ``notes``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

FEATURE_NAMES = (
    "HF_MTW_IF", "ke_2x", "ke_1x", "ke_4x", "lost_motion", "hysteresis", "compliance_residual", "te_rms",
    "ke_indicator", "cs_gain", "cs_coulomb", "cs_rms_ratio", "efficiency", "W_load",
)
#: order-tracked phasor components a_k, b_k [rad] of the k x wave-generator orders (sin, cos of k theta_m):
#: theta_m is the absolute motor angle, so the phasors of a mission's windows add coherently
PHASOR_NAMES = tuple(f"ke_{k}x_{p}" for k in (1, 2, 4) for p in ("s", "c"))


@dataclass
class StiffnessLaw:
    """Catalogue three-slope torsional stiffness (PHYSICS.md 2.1), odd-symmetric.

    Defaults: CSF/CSG size 32, ratio >= 80 (T1 29 N m, T2 108 N m, K1 6.7e4,
    K2 1.1e5, K3 1.2e5 N m/rad).
    """

    T1: float = 29.0  # N m
    T2: float = 108.0  # N m
    K1: float = 6.7e4  # N m/rad
    K2: float = 1.1e5
    K3: float = 1.2e5

    def __post_init__(self) -> None:
        for k in ("T1", "T2", "K1", "K2", "K3"):
            v = getattr(self, k)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"StiffnessLaw.{k} must be finite and > 0, got {v!r}")
        if self.T2 <= self.T1:
            raise ValueError(f"StiffnessLaw: T2 ({self.T2}) must exceed T1 ({self.T1})")

    def twist(self, T: np.ndarray) -> np.ndarray:
        """Elastic twist phi(T) [rad] for torque T [N m]."""
        a = np.abs(T)
        phi = np.where(
            a <= self.T1, a / self.K1,
            np.where(a <= self.T2, self.T1 / self.K1 + (a - self.T1) / self.K2,
                     self.T1 / self.K1 + (self.T2 - self.T1) / self.K2 + (a - self.T2) / self.K3))
        return np.sign(T) * phi


@dataclass
class FeatureConfig:
    """Parameters of the feature extraction (all SI)."""

    stiffness: StiffnessLaw = field(default_factory=StiffnessLaw)
    eta_nom: float = 0.75  # nominal efficiency for Q_hat = N eta tau_m when Q_red is missing
    min_wg_turns: float = 2.0  # wave-generator turns needed to resolve the orders
    q_deadband_frac: float = 0.02  # |Q| below this fraction of max|Q| has sgn(Q) = 0 (reversal zone)
    beta_T: float = 0.025  # 1/K, viscosity-temperature coefficient (times the exponent n)
    T_ref: float = 25.0  # degC, reference temperature of cs_gain
    hf_name: str = "ke_2x"  # which feature is HF_MTW_IF


def _seg_gradient(y: np.ndarray, t: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """dy/dt by central differences inside each segment; NaN at segment ends and around NaNs."""
    dy = np.full(len(y), np.nan)
    if len(y) < 3:
        return dy
    same = (seg[2:] == seg[:-2]) & (seg[1:-1] == seg[2:])
    dt = t[2:] - t[:-2]
    with np.errstate(invalid="ignore", divide="ignore"):
        dy[1:-1] = np.where(same & (dt > 0), (y[2:] - y[:-2]) / dt, np.nan)
    return dy


def block_features(
    t: np.ndarray,
    theta_m: np.ndarray,
    theta_f: np.ndarray,
    omega_m: np.ndarray,
    omega_f: np.ndarray,
    tau_m: np.ndarray,
    Q_red: np.ndarray,
    gear_ratio: float,
    torque_constant: float,
    temperature: np.ndarray | None = None,
    segment: np.ndarray | None = None,
    cfg: FeatureConfig | None = None,
    source: str = "block",
) -> dict:
    """All health features of one block of joint-state samples (the streaming core).

    Arrays are on one time base ``t`` [s]; NaN marks missing samples.
    Returns a dict with the names of ``FEATURE_NAMES`` plus ``n_used``,
    ``duration``, ``torque_source`` and ``notes``. Raises ``ValueError``
    naming ``source`` on wrong shapes or absurd metadata.
    """
    cfg = cfg or FeatureConfig()
    N, kt = float(gear_ratio), float(torque_constant)
    if not np.isfinite(N) or N <= 1:
        raise ValueError(f"{source}: gear_ratio must be finite and > 1, got {gear_ratio!r}")
    if not np.isfinite(kt) or kt <= 0:
        raise ValueError(f"{source}: torque_constant must be finite and > 0, got {torque_constant!r}")
    arrs = [np.asarray(a, dtype=float) for a in (t, theta_m, theta_f, omega_m, omega_f, tau_m, Q_red)]
    n = len(arrs[0])
    if any(a.ndim != 1 or len(a) != n for a in arrs):
        raise ValueError(f"{source}: signals must be 1-D arrays of equal length, got {[a.shape for a in arrs]}")
    t, theta_m, theta_f, omega_m, omega_f, tau_m, Q_red = arrs
    seg = np.zeros(n, np.int64) if segment is None else np.asarray(segment)
    notes: list[str] = []
    out = {k: float("nan") for k in FEATURE_NAMES + PHASOR_NAMES}
    out.update(n_used=0, duration=float(t[-1] - t[0]) if n > 1 else 0.0, torque_source="none", notes=notes)
    if n < 20:
        notes.append(f"only {n} samples")
        return out

    # torque: measured, or reflected motor torque
    q_ok = np.isfinite(Q_red)
    if q_ok.mean() >= 0.5:
        Q = Q_red
        out["torque_source"] = "Q_red"
    else:
        Q = N * cfg.eta_nom * tau_m
        out["torque_source"] = "N*eta*tau_m"
        notes.append(f"Q_red missing on {100 * (1 - q_ok.mean()):.0f} % of samples: using N*eta_nom*tau_m")

    # Archard exposure: mean |Q||omega_m| over valid samples times the duration
    p = np.abs(Q) * np.abs(omega_m)
    pv = np.isfinite(p)
    if pv.any():
        out["W_load"] = float(np.mean(p[pv]) * out["duration"])

    # transmission error with the nominal elastic twist removed
    raw_te = theta_f - theta_m / N
    rt = raw_te[np.isfinite(raw_te)]
    if len(rt) > 20 and np.std(rt) < 1e-10:
        # theta_m was derived from theta_f (e.g. an import without an input encoder): no transmission error
        notes.append("theta_f - theta_m/N is identically constant: theta_m looks derived from theta_f; "
                     "kinematic-error features are not observable in this bag")
        raw_te = np.full(n, np.nan)
    te = raw_te - cfg.stiffness.twist(Q)
    dQ = _seg_gradient(Q, t, seg)
    qmax = np.nanmax(np.abs(Q)) if np.isfinite(Q).any() else 0.0
    sgnQ = np.where(np.abs(Q) > cfg.q_deadband_frac * qmax, np.sign(Q), 0.0)
    ok = np.isfinite(te) & np.isfinite(Q) & np.isfinite(dQ)
    out["n_used"] = int(ok.sum())
    if ok.sum() < 20:
        notes.append("fewer than 20 valid transmission-error samples")
    else:
        th = theta_m[ok]
        turns = np.ptp(th) / (2 * np.pi)
        cols = [np.ones(ok.sum()), Q[ok] / max(qmax, 1e-9), sgnQ[ok], np.sign(dQ[ok])]
        names = ["c0", "cQ", "c_bl", "c_hy"]
        harm = turns >= cfg.min_wg_turns
        if harm:
            for k in (1, 2, 4):
                cols += [np.sin(k * th), np.cos(k * th)]
                names += [f"s{k}", f"c{k}"]
        else:
            notes.append(f"only {turns:.2f} wave-generator turns: orders not resolved")
        A = np.column_stack(cols)
        y = te[ok]
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        coef, *_ = np.linalg.lstsq(A / scale, y - np.mean(y), rcond=None)
        coef = coef / scale
        c = dict(zip(names, coef))
        out["compliance_residual"] = float(c["cQ"] / max(qmax, 1e-9))
        out["lost_motion"] = float(2 * abs(c["c_bl"]))
        out["hysteresis"] = float(2 * abs(c["c_hy"]))
        elastic = A[:, :2] @ coef[:2]
        out["te_rms"] = float(np.sqrt(np.mean((y - np.mean(y) - elastic) ** 2)))
        kin = A[:, 2:] @ coef[2:]
        out["ke_indicator"] = float(np.sqrt(np.mean((kin - kin.mean()) ** 2)))
        if harm:
            for k in (1, 2, 4):
                out[f"ke_{k}x"] = float(np.hypot(c[f"s{k}"], c[f"c{k}"]))
                out[f"ke_{k}x_s"], out[f"ke_{k}x_c"] = float(c[f"s{k}"]), float(c[f"c{k}"])
    out["HF_MTW_IF"] = out.get(cfg.hf_name, float("nan"))

    # current-speed gain, temperature-compensated
    i_q = tau_m / kt
    dw = _seg_gradient(omega_m, t, seg)
    Tt = np.full(n, cfg.T_ref) if temperature is None else np.asarray(temperature, float)
    if not np.isfinite(Tt).any():
        Tt = np.full(n, cfg.T_ref)
        notes.append("no temperature: cs_gain not temperature-compensated")
    fT = np.exp(-cfg.beta_T * (np.where(np.isfinite(Tt), Tt, np.nanmean(Tt)) - cfg.T_ref))
    okc = np.isfinite(i_q) & np.isfinite(omega_m) & np.isfinite(dw)
    use_q = out["torque_source"] == "Q_red"
    if use_q:
        okc &= np.isfinite(Q)
    if okc.sum() >= 20 and np.ptp(omega_m[okc]) > 0:
        w = omega_m[okc]
        cols = [np.sign(w), w * fT[okc], dw[okc], np.ones(okc.sum())]
        if use_q:
            cols.append(Q[okc])
        A = np.column_stack(cols)
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        coef, *_ = np.linalg.lstsq(A / scale, i_q[okc], rcond=None)
        out["cs_gain"] = float(coef[1] / scale[1])
        out["cs_coulomb"] = float(abs(coef[0] / scale[0]))
        out["cs_rms_ratio"] = float(np.sqrt(np.mean(i_q[okc] ** 2)) / max(np.sqrt(np.mean(w**2)), 1e-12))
    else:
        notes.append("not enough valid current/speed samples for cs_gain")
    if use_q:
        pin, pout = tau_m * omega_m, Q * omega_f
        mot = np.isfinite(pin) & np.isfinite(pout) & (pin > 0) & (pout > 0)
        if mot.sum() >= 20 and pin[mot].sum() > 0:
            out["efficiency"] = float(pout[mot].sum() / pin[mot].sum())
    return out


def mission_features(mission, cfg: FeatureConfig | None = None) -> dict:
    """Features of a whole :class:`hd_bag.mission.Mission` (never reads ``mission.sim``)."""
    m = mission
    src = getattr(m.report, "path", "") or f"{m.meta.actuator_id}/mission {m.meta.mission_index}"
    try:
        temp = m.temperature_on_t("gearbox")
    except Exception:  # noqa: BLE001 - temperature is optional
        temp = None
    f = block_features(m.t, m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red,
                       m.meta.gear_ratio, m.meta.torque_constant, temp, m.segment, cfg, src)
    f["mission_index"] = int(m.meta.mission_index)
    f["operating_hours"] = float(m.meta.operating_hours)
    f["actuator_id"] = str(m.meta.actuator_id)
    return f


def window_features(mission, window_s: float = 10.0, hop_s: float | None = None,
                    cfg: FeatureConfig | None = None) -> list[dict]:
    """Features per window of ``window_s`` seconds (hop ``hop_s``, default = window) over a mission.

    The onboard node calls :func:`block_features` on its own blocks; this is
    the same computation in batch. Each dict has ``t_start`` and ``t_end`` [s].
    """
    if not np.isfinite(window_s) or window_s <= 0:
        raise ValueError(f"window_s must be > 0, got {window_s!r}")
    hop = window_s if hop_s is None else float(hop_s)
    if hop <= 0:
        raise ValueError(f"hop_s must be > 0, got {hop_s!r}")
    m = mission
    temp = m.temperature_on_t("gearbox")
    dt = float(np.median(np.diff(m.t))) if m.n > 1 else 0.0
    # a window is complete when it ends within one sample period of the last stamp
    starts = np.arange(m.t[0], max(m.t[-1] + dt - window_s, m.t[0]) + 1e-9, hop) if m.n else []
    lo = np.searchsorted(m.t, starts, side="left")
    hi = np.searchsorted(m.t, np.asarray(starts) + window_s, side="left")
    out = []
    for s, a, b in zip(starts, lo, hi):
        sl = slice(a, b)
        f = block_features(m.t[sl], m.theta_m[sl], m.theta_f[sl], m.omega_m[sl], m.omega_f[sl], m.tau_m[sl],
                           m.Q_red[sl], m.meta.gear_ratio, m.meta.torque_constant, temp[sl], m.segment[sl], cfg,
                           f"{m.meta.actuator_id}/mission {m.meta.mission_index} window {s:.1f} s")
        f["t_start"], f["t_end"] = float(s), float(s + window_s)
        out.append(f)
    return out


# ---- the per-mission prognostic observation: one definition for the node and batch -------------------
#: window length [s] of the observation: the onboard node's ``window_s`` default (``OnboardConfig.window_s``)
OBS_WINDOW_S = 1.0
#: features reduced by summing the windows (exposures); every other feature is reduced by the median
SUM_FEATURES = ("W_load",)


def onboard_window_features(mission, window_s: float = OBS_WINDOW_S, cfg: FeatureConfig | None = None) -> list[dict]:
    """Batch twin of the onboard node's feature windows: the rows the prognostic node receives.

    Same windows as :class:`hd_onboard.core.OnboardCore` (index ``floor(t / window_s)``
    with ``t = (stamp_ns - t0_ns) * 1e-9`` since the first stamp; empty windows
    are not emitted, the last one is closed at the end of the mission) and the
    same call as the onboard node's window feature function: :func:`block_features`
    on the raw (unheld) samples of the window, time relative to its first stamp,
    no segment labels. Temperature is the mission's gearbox temperature on the
    samples (the node holds its latest value; only ``cs_gain`` depends on it,
    not the observation). Each dict has ``t_start`` [s] and ``n``.
    """
    if not (isinstance(window_s, (int, float)) and np.isfinite(window_s) and 0 < window_s <= 3600):
        raise ValueError(f"window_s must be in (0, 3600] s, got {window_s!r}")
    m = mission
    src = getattr(m.report, "path", "") or f"{m.meta.actuator_id}/mission {m.meta.mission_index}"
    if m.n == 0:
        return []
    # the stamps the node sees (replay publishes the original stamps), and the core's drop of non-increasing ones
    stamps_ns = int(m.t0_ns) + np.round(np.asarray(m.t) * 1e9).astype(np.int64)
    keep = stamps_ns > np.maximum.accumulate(np.concatenate([[np.iinfo(np.int64).min], stamps_ns[:-1]]))
    idx = np.flatnonzero(keep)
    stamps_ns = stamps_ns[idx]
    t = (stamps_ns - stamps_ns[0]) * 1e-9
    widx = np.floor(t / window_s).astype(np.int64)
    cut = np.flatnonzero(np.diff(widx)) + 1
    try:
        temp = np.asarray(m.temperature_on_t("gearbox"), float)[idx]
    except Exception:  # noqa: BLE001 - temperature is optional
        temp = None
    stamp_s = stamps_ns * 1e-9
    sig = [np.asarray(getattr(m, k), float)[idx] for k in ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")]
    out = []
    for a, b in zip(np.concatenate([[0], cut]), np.concatenate([cut, [len(t)]])):
        ts = stamp_s[a:b]
        tw = None if temp is None else temp[a:b]
        f = block_features(ts - ts[0], *(s[a:b] for s in sig), m.meta.gear_ratio, m.meta.torque_constant,
                           tw, None, cfg, f"{src} window {int(widx[a])}")
        f["t_start"], f["n"] = float(widx[a] * window_s), float(b - a)
        out.append(f)
    return out


def window_feature_fn(meta: dict, gear_ratio: float):
    """The onboard node's window feature function ``fn(stamps_s, V, temperature) -> {name: number}``:
    :func:`block_features` of one closed window of the onboard core (``V`` columns theta_m, theta_f,
    omega_m, omega_f, tau_m, Q_red; time relative to the window's first stamp; torque constant from the
    mission metadata, 0.3 N*m/A when absent), as :func:`onboard_window_features` computes in batch."""
    k_t = float(meta.get("torque_constant") or 0.3)
    N = float(gear_ratio)

    def fn(stamps_s, V, temperature):
        t = stamps_s - stamps_s[0]
        temp = np.full(len(t), temperature) if np.isfinite(temperature) else None
        f = block_features(t, V[:, 0], V[:, 1], V[:, 2], V[:, 3], V[:, 4], V[:, 5], N, k_t,
                           temp, None, None, "onboard window")
        return {k: v for k, v in f.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}

    return fn


def mission_observation(windows) -> dict:
    """The per-mission prognostic observation from its window feature rows (node and batch alike).

    ``windows``: the mission's window rows, either :func:`block_features` dicts
    (keys ``HF_MTW_IF``, ...) or the onboard node's published rows (keys
    ``feat.HF_MTW_IF``, ...).

    * Kinematic-error orders ``ke_1x``, ``ke_2x``, ``ke_4x`` [rad]: synchronous
      (coherent) average over the windows, ``|mean_w (a_k + i b_k)|`` from the
      window phasors :data:`PHASOR_NAMES` (``theta_m`` is absolute, so the order
      keeps its phase across windows while the noise does not): the noise and
      the Rayleigh bias of short-window amplitudes fall with the number of
      windows, as in a whole-mission fit. ``HF_MTW_IF`` is the coherent value of
      the order it equals in the rows (``ke_2x`` by default). Rows without
      phasors (older onboard versions): median of the window amplitudes.
    * Exposures :data:`SUM_FEATURES`: ``W_load`` [J] is the sum over the windows
      (the mission's Archard load-sliding integral).
    * Every other feature: median of its finite window values.

    NaN where no window has a value. Also ``n_windows`` and ``n_windows_hf``
    (windows with a finite ``HF_MTW_IF``).
    """
    rows = list(windows)
    for i, r in enumerate(rows):
        if not isinstance(r, dict):
            raise TypeError(f"mission_observation: window {i} is a {type(r).__name__}, expected a dict")

    def col(name: str) -> np.ndarray:
        v = np.full(len(rows), np.nan)
        for i, r in enumerate(rows):
            x = r.get(name, r.get("feat." + name, np.nan))
            if isinstance(x, (int, float, np.floating, np.integer)) and not isinstance(x, bool):
                v[i] = float(x)
        return v

    out: dict = {}
    cols = {k: col(k) for k in FEATURE_NAMES}
    for k, v in cols.items():
        v = v[np.isfinite(v)]
        if not len(v):
            out[k] = float("nan")
        else:
            out[k] = float(np.sum(v)) if k in SUM_FEATURES else float(np.median(v))
    hf = cols["HF_MTW_IF"]
    out["n_windows_hf"] = int(np.isfinite(hf).sum())
    for k in (1, 2, 4):
        a, b = col(f"ke_{k}x_s"), col(f"ke_{k}x_c")
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.any():
            coh = float(np.hypot(a[ok].mean(), b[ok].mean()))
            amp = cols[f"ke_{k}x"]
            same = np.isfinite(hf) & (hf == amp)
            out[f"ke_{k}x"] = coh
            if same.any() and same.sum() == np.isfinite(hf).sum():
                out["HF_MTW_IF"] = coh
    out["n_windows"] = len(rows)
    return out


def mission_observation_features(mission, window_s: float = OBS_WINDOW_S, cfg: FeatureConfig | None = None) -> dict:
    """Batch per-mission observation: :func:`mission_observation` of :func:`onboard_window_features`.

    What the prognostic node computes from the onboard node's rows of the same
    mission (tested equal); plus ``mission_index``, ``operating_hours``,
    ``actuator_id`` and ``window_s``. Never reads ``mission.sim``.
    """
    m = mission
    f = mission_observation(onboard_window_features(m, window_s, cfg))
    f.update(mission_index=int(m.meta.mission_index), operating_hours=float(m.meta.operating_hours),
             actuator_id=str(m.meta.actuator_id), window_s=float(window_s))
    return f
