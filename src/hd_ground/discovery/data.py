"""Turn contract missions into the signal table discovery works on.

Only measured contract signals are used (``/sim/...`` is never read here).
Rows with a non-finite value in any signal that is in use are dropped and the
count is reported. Each bag is cut into contiguous time blocks: fit/held-out
splits and cross-validation folds are made of whole blocks or bags, never of
interleaved samples (neighbouring samples are correlated; a sample split would
overstate how well a term generalises). Logged speeds are put on their angles'
time base first (:func:`speed_timing`: an identified delay of the drive's speed
estimate, not an assumed filter).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hd_bag.mission import Mission
# the re-timing equation and its derivative live in the twin (one place: the twin applies the same re-timing)
from hd_twin.speedtiming import DEFAULT_WINDOW_S as DEFAULT_RETIME_WINDOW_S
from hd_twin.speedtiming import retime_speed  # noqa: F401  (re-exported)
from hd_twin.speedtiming import sg2_derivative as _derivative


class DiscoveryError(ValueError):
    """Input discovery cannot work with; the message names the file and the problem."""


@dataclass
class Dataset:
    signals: dict[str, np.ndarray]  # name -> (n,) float64, finite, SI units
    bag: np.ndarray  # (n,) bag index
    block: np.ndarray  # (n,) global time-block index (blocks never span bags)
    tfrac: np.ndarray  # (n,) time fraction within its bag, 0..1
    t: np.ndarray  # (n,) s within its bag
    segment: np.ndarray  # (n,) global segment index (no differentiation across it)
    bag_names: list[str]
    gear_ratio: float
    torque_constant: float
    notes: list[str] = field(default_factory=list)
    speed_lags: dict[str, float] = field(default_factory=dict)  # speed -> identified delay (s) it was re-timed by
    # the acceleration used when not the default (core.choose_alpha_window): {"window_s", "timing"}
    alpha_window: dict = field(default_factory=dict)
    # the output angle's smoothing window in samples for the twist (core.choose_twist_window; 0: as logged)
    twist_window: int = 0
    # the torque sample's skew after the angle's [s]: position harmonics are taken at theta + skew * omega
    # (hd_twin.terms.retimed_angle; core.choose_angle_timing; 0: at the logged angle)
    angle_skew: float = 0.0
    # the derivative window [s] of the logged speeds' re-timing (omega + tau omega'; core.choose_retime_window):
    # the delays in ``speed_lags`` were identified with it and the speeds re-timed with it
    speed_window_s: float = DEFAULT_RETIME_WINDOW_S

    @property
    def n(self) -> int:
        return len(self.bag)

    def subset(self, mask: np.ndarray) -> "Dataset":
        return Dataset({k: v[mask] for k, v in self.signals.items()}, self.bag[mask], self.block[mask],
                       self.tfrac[mask], self.t[mask], self.segment[mask], self.bag_names, self.gear_ratio,
                       self.torque_constant, list(self.notes), dict(self.speed_lags), dict(self.alpha_window),
                       self.twist_window, self.angle_skew, self.speed_window_s)


def with_angle_skew(ds: Dataset, skew_s: float) -> Dataset:
    """``ds`` (same rows and signals) with its position harmonics to be taken at the angle re-timed by the
    acquisition skew ``skew_s`` [s] (``Dataset.angle_skew``; the library's harmonic candidates read it)."""
    out = ds.subset(np.ones(ds.n, bool))
    out.angle_skew = float(skew_s)
    return out


def _lag_sums(omega: np.ndarray, theta: np.ndarray, t: np.ndarray, seg: np.ndarray,
              window_s: float) -> tuple[float, float, float, int]:
    """Normal-equation sums of omega - theta' = -tau theta'' over the finite segments of one mission:
    (sum a r, sum a a, sum r r, n) with r = omega - theta' (central differences), a = theta'' (the smoothed
    derivative of theta')."""
    sar = saa = srr = 0.0
    n = 0
    for sg in np.unique(seg):
        idx = np.flatnonzero(seg == sg)
        if len(idx) < 7:
            continue
        ts, th, w = t[idx], theta[idx], omega[idx]
        if not (np.all(np.isfinite(th)) and np.all(np.isfinite(w))):
            continue
        rate = np.gradient(th, ts)
        acc = _derivative(rate, ts, np.zeros(len(idx), int), window_s)
        ok = np.isfinite(acc)
        r, a = w[ok] - rate[ok], acc[ok]
        sar += float(a @ r)
        saa += float(a @ a)
        srr += float(r @ r)
        n += int(ok.sum())
    return sar, saa, srr, n


def speed_lag(missions: list[Mission], speed: str, angle: str, *,
              window_s: float = 0.02) -> tuple[float, float]:
    """Delay of a logged speed behind the derivative of its logged angle, s, and its standard error.

    A drive's speed estimate is the encoder angle differenced and low-pass filtered (and a logger may
    average it over the log period), so it lags or leads the angle's own rate; a first-order filter with
    time constant tau delays it by tau at low frequency: omega(t) ~ theta'(t - tau) ~ theta'(t) - tau theta''(t).
    tau by least squares of omega - theta' on -theta'' pooled over the missions (one actuator type, one
    drive: one sensor), per segment (never across a gap); the SE from the residual (white-noise
    assumption: optimistic for quantisation noise, hence the 3-SE rule of :func:`speed_timing`). NaN where
    the angle never accelerates.
    """
    sar = saa = srr = 0.0
    n = 0
    for m in missions:
        seg = np.asarray(m.segment if m.segment is not None else np.zeros(m.n, int))
        x = _lag_sums(np.asarray(getattr(m, speed), float), np.asarray(getattr(m, angle), float),
                      np.asarray(m.t, float), seg, window_s)
        sar, saa, srr, n = sar + x[0], saa + x[1], srr + x[2], n + x[3]
    if saa <= 0 or n < 3:
        return float("nan"), float("nan")
    tau = -sar / saa
    rss = max(srr - sar * sar / saa, 0.0)
    return float(tau), float(np.sqrt(rss / (n - 1) / saa))


def speed_timing(missions: list[Mission], window_s: float = 0.02) -> tuple[dict[str, float], list[str]]:
    """Identified sensor model of the logged speeds: ``{speed: tau}`` to re-time, and notes.

    Why: the friction acts on the shaft's speed at the instant its torque is logged, and the encoder angle
    is a point sample without dynamics, so a speed estimate that lags (a drive's filtered estimate) bends
    every speed-dependent term in transients (a Stribeck curve fitted on lagged speeds is wrong at
    constant speed). Re-timed only when the delay is identified (|tau| > 3 SE) and small enough for the
    first-order inverse (|tau| < half the derivative window); otherwise kept as logged, with the reason.
    Whether the angle itself is on the torque's time base is not visible here: the pipeline keeps the re-timed
    speeds only when the fit bags' tau_m baseline prefers them (``core.choose_speed_timing``).
    """
    lags: dict[str, float] = {}
    notes: list[str] = []
    for speed, angle in (("omega_m", "theta_m"), ("omega_f", "theta_f")):
        tau, se = speed_lag(missions, speed, angle, window_s=window_s)
        if not np.isfinite(tau) or abs(tau) <= 3.0 * se:
            continue
        if abs(tau) >= 0.5 * window_s:
            notes.append(f"{speed}: the logged speed lags the derivative of {angle} by {tau * 1e3:.3g} +- {se * 1e3:.2g} "
                         f"ms, beyond the first-order re-timing (< {0.5e3 * window_s:g} ms); used as logged")
            continue
        lags[speed] = tau
        notes.append(f"{speed}: the logged speed lags the derivative of {angle} by {tau * 1e3:.3g} +- {se * 1e3:.2g} ms "
                     "(least squares over all bags: a drive's filtered speed estimate or a logger's averaging); "
                     f"re-timed to the angle's instants, {speed} + tau d{speed}/dt, before any model sees it")
    return lags, notes



def angle_resolution(theta: np.ndarray, segment: np.ndarray | None = None, *, tol: float = 0.05,
                     min_share: float = 0.9) -> float:
    """Quantisation step [rad] of a logged angle, or 0.0 if it is not visibly quantised.

    An encoder logs whole counts: every non-zero increment of the angle within a segment is then a
    whole multiple of one step q (the smallest increment). Accepted when at least ``min_share`` of the
    non-zero increments lie within ``tol`` steps of a whole multiple of q; a continuous (noisy,
    interpolated or filtered) angle fails that test and gives 0.0.
    """
    x = np.asarray(theta, float)
    d = np.abs(np.diff(x))
    if segment is not None:
        seg = np.asarray(segment)
        d = d[seg[1:] == seg[:-1]]
    d = d[np.isfinite(d) & (d > 0)]
    if len(d) < 20:
        return 0.0
    # the smallest increments, robust to a few rounding leftovers far below the step
    q = float(np.median(d[d <= 1.5 * np.quantile(d, 0.05)]))
    if not q > 0:
        return 0.0
    k = d / q
    if np.mean(np.abs(k - np.round(k)) < tol) < min_share:
        return 0.0
    return q


def play(x: np.ndarray, r: float, segment: np.ndarray | None = None) -> np.ndarray:
    """Play (backlash) operator of half-width ``r`` on the time-ordered ``x``: the output follows x only once
    x has moved more than r past it, so reversals of x smaller than 2 r leave it unchanged. Restarts at
    each new ``segment`` (at the segment's first sample)."""
    x = np.asarray(x, float)
    n = len(x)
    if n == 0 or not r > 0:
        return x.copy()
    seg = np.zeros(n, int) if segment is None else np.asarray(segment)
    start = np.r_[True, seg[1:] != seg[:-1]].tolist()
    xs = x.tolist()
    o = [0.0] * n
    c = xs[0]
    for i in range(n):
        v = xs[i]
        if start[i] or not (c == c):  # a new segment (or a NaN carried): restart on the sample
            c = v
        elif v > c + r:
            c = v - r
        elif v < c - r:
            c = v + r
        o[i] = c
    return np.asarray(o)


#: The motor acceleration's default derivative window [s] (core.choose_alpha_window moves off it when identified).
DEFAULT_ALPHA_WINDOW_S = 0.02


def signals_of_mission(m: Mission, *, deriv_window_s: float = DEFAULT_ALPHA_WINDOW_S,
                       speed_lags: dict[str, float] | None = None,
                       alpha_window_s: float | None = None,
                       alpha_timing: bool = False,
                       retime_window_s: float | None = None) -> tuple[dict[str, np.ndarray], list[str]]:
    """Signal table of one mission (full length, may contain NaN) and notes on what was done.

    ``speed_lags``: ``{speed: tau}`` from :func:`speed_timing`; those logged speeds are re-timed, with the
    derivative window ``retime_window_s`` (default ``deriv_window_s``; ``core.choose_retime_window``).
    ``alpha_window_s``: window of the motor acceleration's derivative filter (default ``deriv_window_s``;
    ``core.choose_alpha_window`` identifies it on the fit bags). ``alpha_timing``: also ``alpha_m_dot``, the
    derivative of alpha_m with the same window (the baseline's J tau_a alpha_m' column: the inertia torque's
    timing against the logged torque)."""
    notes: list[str] = []
    name = m.report.path or m.meta.actuator_id
    n = m.n
    if n < 10:
        raise DiscoveryError(f"{name}: only {n} joint-state samples; discovery needs at least a few seconds of data")
    N = float(m.meta.gear_ratio)
    kt = float(m.meta.torque_constant)
    if not (np.isfinite(N) and N > 0 and np.isfinite(kt) and kt > 0):
        raise DiscoveryError(f"{name}: gear_ratio={N} and torque_constant={kt} must be finite and positive")
    seg = np.asarray(m.segment if m.segment is not None else np.zeros(n, int))
    notes += [f"{name}: suspect data (the reader's cross-checks): {x}" for x in getattr(m.report, "suspect", [])]
    s: dict[str, np.ndarray] = {}
    for k in ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red"):
        v = np.asarray(getattr(m, k), float)
        if v.shape != (n,):
            raise DiscoveryError(f"{name}: signal {k} has shape {v.shape}, expected ({n},)")
        s[k] = v
    if np.mean(np.isfinite(s["omega_m"])) < 0.5 and np.mean(np.isfinite(s["theta_m"])) > 0.9:
        s["omega_m"] = _derivative(s["theta_m"], m.t, seg, deriv_window_s)
        notes.append(f"{name}: omega_m mostly missing; derived from theta_m")
    else:
        for w, tau in (speed_lags or {}).items():
            s[w] = retime_speed(s[w], m.t, seg, tau, deriv_window_s if retime_window_s is None else retime_window_s)
    s["i_q"] = s["tau_m"] / kt
    aw_s = deriv_window_s if alpha_window_s is None else alpha_window_s
    s["alpha_m"] = _derivative(s["omega_m"], m.t, seg, aw_s)
    if alpha_timing:
        s["alpha_m_dot"] = _derivative(s["alpha_m"], m.t, seg, aw_s)
    if np.any(np.isfinite(s["Q_red"])):
        s["Q_red_over_N"] = s["Q_red"] / N
    # the output's acceleration through the gear (the twist's own acceleration is negligible against it):
    # the Q_red baseline's inertia column (the flange between the twist and the torque sensor, PHYSICS.md r4)
    s["alpha_f"] = s["alpha_m"] / N
    s["phi"] = s["theta_f"] - s["theta_m"] / N  # output-side twist (hd_twin.physics convention), rad
    s["phi_dot"] = s["omega_f"] - s["omega_m"] / N
    # wind-up: input leading the output; the transmitted torque is + K windup (PHYSICS.md 1.2:
    # delta_m = ... - r_m phi), so K and c come out positive
    s["windup"] = -s["phi"]
    s["windup_dot"] = -s["phi_dot"]
    # the twist as its quantised encoders can resolve it (errors in variables): a reversal of the measured
    # twist by up to its measurement step (output-encoder step + motor-encoder step / N) and back is a count
    # toggling, not a reversal of the load; the twist-side hysteresis state is also tried on this play of
    # half-width one step (1.001: the steps' float rounding), equal to the twist where neither angle is
    # visibly quantised
    res_w = angle_resolution(s["theta_f"], seg) + angle_resolution(s["theta_m"], seg) / N
    s["windup_q"] = play(s["windup"], 1.001 * res_w, seg) if res_w > 0 else s["windup"].copy()
    from hd_bag.mission import MAX_TWIST_OFFSET

    ph = s["phi"][np.isfinite(s["phi"])]
    if len(ph) and abs(float(np.median(ph))) > MAX_TWIST_OFFSET:
        # motor and output encoders without a common zero: the twist is off by a constant far
        # beyond any wind-up, so neither the twist terms nor Q_red (modelled through them) can be
        # analysed; the motor side (tau_m vs theta_m, omega_m) is unaffected
        notes.append(f"{name}: theta_f - theta_m / N has median {float(np.median(ph)):.6g} rad (> {MAX_TWIST_OFFSET:g} "
                     "rad: encoders without a common zero); twist and Q_red left out of the analysis")
        for k in ("phi", "phi_dot", "windup", "windup_dot", "windup_q", "Q_red"):
            s[k] = np.full(n, np.nan)
        s.pop("Q_red_over_N", None)
    temp = m.temperature_on_t("gearbox")
    if np.any(np.isfinite(temp)):
        s["temperature"] = temp
    tw = m.temperature_on_t("motor_winding")
    if np.any(np.isfinite(tw)) and "motor_winding" in m.temperatures:
        s["temperature_winding"] = tw
    return s, notes


def with_smoothed_twist(ds: Dataset, window: int) -> Dataset:
    """``ds`` with the twist read through a smoothed output angle: windup = theta_m / N - SG(theta_f).

    SG: the centred quadratic Savitzky-Golay smoother of ``window`` samples (odd, >= 5), per segment (segments
    not longer than the window keep the logged angle). The twist is a small difference of two encoder angles;
    the output encoder's step (2 pi / 2^16 = 9.6e-5 rad for 16 bits) is a large fraction of it, and that
    quantisation error in the regressor (errors in variables) is no white noise on Q_red: it biases the
    twist-to-torque law's shape with the twist's distribution, differently per mission. The motor angle is
    divided by N (its step with it), so only the output angle is smoothed; the twist rate (from the speeds) and
    ``windup_q`` (the encoders' play, a model of the logged resolution) are unchanged. A quadratic smoother keeps
    a motion that is locally quadratic over the window; whether it helps is decided on the fit bags
    (``core.choose_twist_window``), never assumed. The smoother is the twin's (``hd_twin.twistsmooth.smooth_angle``),
    which the twin version discovery writes applies too (``config.json:twist_smoothing``). Returns a new dataset;
    ``ds`` is unchanged."""
    from hd_twin.twistsmooth import smooth_angle

    w = int(window)
    if w < 5 or w % 2 == 0:
        raise ValueError(f"twist smoothing window must be odd and >= 5 samples, got {window}")
    sig = dict(ds.signals)
    sm = smooth_angle(np.asarray(sig["theta_f"], float), ds.segment, w, 2)
    sig["phi"] = sm - sig["theta_m"] / ds.gear_ratio
    sig["windup"] = -sig["phi"]
    out = Dataset(sig, ds.bag, ds.block, ds.tfrac, ds.t, ds.segment, ds.bag_names, ds.gear_ratio, ds.torque_constant,
                  list(ds.notes), dict(ds.speed_lags), dict(ds.alpha_window), w, ds.angle_skew, ds.speed_window_s)
    return out


def dataset_from_missions(missions: list[Mission], names: list[str] | None = None, *, blocks_per_bag: int = 5,
                          required: tuple[str, ...] = ("theta_m", "omega_m", "tau_m"),
                          retime_speeds: bool = True, alpha_window_s: float | None = None,
                          alpha_timing: bool = False, retime_window_s: float | None = None) -> Dataset:
    """Concatenate missions into one :class:`Dataset`.

    Logged speeds are first put on their angles' time base by the identified sensor model of
    :func:`speed_timing` (``retime_speeds=False``: as logged), its delays identified and the speeds re-timed with
    the derivative window ``retime_window_s`` (default ``DEFAULT_RETIME_WINDOW_S``, 20 ms;
    ``core.choose_retime_window`` identifies it on the fit bags). ``alpha_window_s``: the motor acceleration's
    derivative window (default: that of :func:`signals_of_mission`); ``alpha_timing``: add ``alpha_m_dot``.

    A signal that is entirely missing in any bag is dropped from all bags (the
    same model must apply everywhere); ``required`` signals must be present.
    """
    if not missions:
        raise DiscoveryError("no missions given")
    names = names or [m.report.path or f"bag{i}" for i, m in enumerate(missions)]
    rw = DEFAULT_RETIME_WINDOW_S if retime_window_s is None else float(retime_window_s)
    lags, notes = speed_timing(missions, window_s=rw) if retime_speeds else ({}, [])
    tables = []
    gear, kt = None, None
    for m, nm in zip(missions, names):
        s, nn = signals_of_mission(m, speed_lags=lags, alpha_window_s=alpha_window_s, alpha_timing=alpha_timing,
                                   retime_window_s=rw)
        tables.append(s)
        notes += nn
        if gear is None:
            gear, kt = float(m.meta.gear_ratio), float(m.meta.torque_constant)
        elif abs(float(m.meta.gear_ratio) - gear) > 1e-9 * gear:
            raise DiscoveryError(f"{nm}: gear_ratio {m.meta.gear_ratio} differs from the first bag's {gear}; "
                                 "discover one actuator type at a time")
    keys = set(tables[0])
    for s, nm in zip(tables, names):
        for k in list(keys):
            if k not in s or not np.any(np.isfinite(s[k])):
                if k in required:
                    raise DiscoveryError(f"{nm}: required signal {k} has no finite sample")
                notes.append(f"{nm}: {k} not measured; not used")
                keys.discard(k)
    keys = sorted(keys)
    cols = {k: [] for k in keys}
    bag, block, tfrac, tt, segm = [], [], [], [], []
    nblk = 0
    segoff = 0
    for i, (m, s, nm) in enumerate(zip(missions, tables, names)):
        ok = np.ones(m.n, bool)
        for k in keys:
            ok &= np.isfinite(s[k])
        if (~ok).sum():
            notes.append(f"{nm}: dropped {(~ok).sum()} of {m.n} samples with a non-finite signal")
        if ok.sum() < 10:
            raise DiscoveryError(f"{nm}: fewer than 10 samples with all signals finite")
        t = m.t - m.t[0]
        frac = t / max(t[-1], 1e-12)
        b = np.minimum((frac * blocks_per_bag).astype(int), blocks_per_bag - 1)
        for k in keys:
            cols[k].append(s[k][ok])
        bag.append(np.full(ok.sum(), i))
        block.append(b[ok] + nblk)
        tfrac.append(frac[ok])
        tt.append(t[ok])
        sg = np.asarray(m.segment)[ok].astype(int)
        segm.append(sg + segoff)
        segoff += int(sg.max()) + 1 if len(sg) else 1
        nblk += blocks_per_bag
    return Dataset({k: np.concatenate(v) for k, v in cols.items()}, np.concatenate(bag), np.concatenate(block),
                   np.concatenate(tfrac), np.concatenate(tt), np.concatenate(segm), list(names), float(gear),
                   float(kt), notes, dict(lags), speed_window_s=rw)
