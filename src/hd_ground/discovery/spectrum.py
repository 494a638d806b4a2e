"""Residual structure analysis: order spectra and conditional dependences.

Order tracking without resampling artefacts: the order spectrum of a residual
r against an angle theta is the angle-domain Fourier integral

    R(k) = 2 * sum_i r_i exp(-j k theta_i) |d theta_i| / sum_i |d theta_i|

i.e. the residual integrated over angle travelled (equivalent to resampling on
a uniform angle grid and taking the DFT, but exact for any speed profile,
reversals included; standstill samples get no weight). |R(k)| is the amplitude
of the order-k component in the residual's unit (N*m) at order k, cycles per
revolution of theta. Evaluated on a grid of orders with numpy, in chunks.

Orders above what the fastest rows sample: an order-k line needs >= 4 samples per period, k |d theta| <= pi / 2.
A log at 1 kHz of a motor at 140 rad/s resolves orders up to ~11 on every row, but at 30 rad/s up to ~50: the
torque ripple of a PMSM (6 p, 12 p electrical orders, e.g. 30 and 60 mechanical for 5 pole pairs) and other
high-order lines are visible in the slower rows. Each order's integral therefore uses the rows that sample it
(``k |d theta_i| <= pi / 2``), normalised by their own angle travelled, and the grid extends to the order whose
rows still travel two revolutions (``LINE_REVOLUTIONS``, the angle a periodicity needs). Lines are found on the
amplitude divided by its white-noise standard error, sqrt(sum w_i^2) / sum w_i (unit residual variance): an order
seen by fewer rows is noisier, and a floor taken over orders of unequal support would call its noise a line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class OrderSpectrum:
    variable: str
    modulator: str  # "" (plain residual) or "sgn(omega_m)" (residual times the sign of motion)
    orders: np.ndarray  # cycles per revolution
    amplitude: np.ndarray  # N*m
    floor: float  # N*m, median amplitude (noise floor), each order scaled to the best-supported order's noise level
    peaks: list[float]  # detected orders, strongest first
    revolutions: float  # angle range covered, revolutions
    # per order, its amplitude's noise level relative to the best-supported order's (>= 1; the floor at an order is
    # floor * noise_scale: an order seen by fewer rows is noisier); None: 1 everywhere
    noise_scale: np.ndarray | None = None


def angle_weights(theta: np.ndarray, segment: np.ndarray | None = None) -> np.ndarray:
    """|d theta| per sample (rad), zero across segment boundaries."""
    d = np.abs(np.gradient(theta))
    if segment is not None and len(segment) > 1:
        br = np.flatnonzero(np.diff(segment) != 0)
        d[br] = 0.0
        d[np.minimum(br + 1, len(d) - 1)] = 0.0
    d[~np.isfinite(d)] = 0.0
    return d


#: samples per period an order needs in a row for that row to enter its integral (k |d theta| <= 2 pi / this)
SAMPLES_PER_PERIOD = 4.0
#: revolutions of angle travelled an order's own rows must cover for the grid to reach that order
LINE_REVOLUTIONS = 2.0


def order_spectrum(
    r: np.ndarray,
    theta: np.ndarray,
    orders: np.ndarray,
    weights: np.ndarray | None = None,
    chunk: int = 64,
    return_se: bool = False,
):
    """Amplitude |R(k)| (unit of r) of the order components of ``r`` against ``theta`` (rad); each order from the
    rows that sample it (``k |d theta| <= 2 pi / SAMPLES_PER_PERIOD``). ``return_se``: also the amplitude's white-noise
    standard error per order for a unit residual variance, sqrt(sum w^2) / sum w over those rows (inf: no row)."""
    r = np.asarray(r, float)
    theta = np.asarray(theta, float)
    w = angle_weights(theta) if weights is None else np.asarray(weights, float)
    ok = np.isfinite(r) & np.isfinite(theta) & (w > 0)
    r, theta, w = r[ok], theta[ok], w[ok]
    out = np.zeros(len(orders))
    se = np.full(len(orders), np.inf)
    if w.sum() <= 0:
        return (out, se) if return_se else out
    step = np.abs(np.gradient(theta)) if len(theta) > 1 else np.zeros(len(theta))
    rc = r - np.average(r, weights=w)
    lim = 2 * np.pi / SAMPLES_PER_PERIOD
    for i in range(0, len(orders), chunk):
        k = orders[i : i + chunk, None]
        wk = w[None, :] * (k * step[None, :] <= lim)
        sw = wk.sum(1)
        ph = k * theta[None, :]
        good = sw > 0
        c = np.einsum("ij,ij->i", np.cos(ph), wk * rc[None, :])
        s = np.einsum("ij,ij->i", np.sin(ph), wk * rc[None, :])
        out[i : i + chunk] = np.where(good, 2.0 * np.hypot(c, s) / np.where(good, sw, 1.0), 0.0)
        se[i : i + chunk] = np.where(good, np.sqrt((wk**2).sum(1)) / np.where(good, sw, 1.0), np.inf)
    return (out, se) if return_se else out


def order_grid(theta: np.ndarray, *, k_max: float = 200.0, max_points: int = 3000) -> tuple[np.ndarray, float]:
    """Order grid (resolution from the angle range covered, top from the per-sample angle step).

    Returns (orders, revolutions covered).
    """
    th = theta[np.isfinite(theta)]
    if len(th) < 2:
        return np.zeros(0), 0.0
    span = float(th.max() - th.min())
    revs = span / (2 * np.pi)
    step = np.abs(np.diff(th))
    step = step[step > 0]
    if revs < 1.0 or len(step) == 0:
        return np.zeros(0), revs
    # Nyquist in the angle domain, with margin: 4 samples per period (SAMPLES_PER_PERIOD), up to the order whose
    # rows (those that sample it so, the slowest first: each order is integrated over its own rows) still travel
    # LINE_REVOLUTIONS revolutions, the angle a periodicity needs to be told from a trend (discovery's rule for
    # position-periodic candidates)
    srt = np.sort(step)
    cum = np.cumsum(srt)
    need = LINE_REVOLUTIONS * 2 * np.pi
    s_step = float(srt[min(np.searchsorted(cum, need), len(srt) - 1)]) if cum[-1] >= need else float(srt[-1])
    k_top = min(k_max, 2 * np.pi / (SAMPLES_PER_PERIOD * s_step))
    dk = max(0.5 / revs, 0.02)  # half the Rayleigh resolution 1/revs
    dk = max(dk, k_top / max_points)
    orders = np.arange(0.5, k_top + dk / 2, dk)
    # the integer orders on the grid too: where the grid is coarser than a line's width (1 / revs; the point cap on a
    # high top), a line between two grid points would lose up to all of its amplitude, and physical lines sit at
    # integer orders of their angle
    orders = np.unique(np.concatenate([orders, np.arange(1.0, np.floor(k_top) + 1.0)]))
    return orders, revs


def find_peaks(orders: np.ndarray, amp: np.ndarray, *, ratio: float = 6.0, max_peaks: int = 6,
               revs: float = 1.0) -> tuple[list[float], float]:
    """Orders of spectral lines standing ``ratio`` times above the median floor.

    A line is a local maximum; orders within the resolution (1/revs) of an
    integer are snapped to it (integer orders are the physical expectation;
    others are reported as they are). Returns (peaks strongest first, floor).
    """
    if len(amp) < 5:
        return [], 0.0
    floor = float(np.median(amp))
    if floor <= 0:
        return [], floor
    lm = np.flatnonzero((amp[1:-1] >= amp[:-2]) & (amp[1:-1] >= amp[2:])) + 1
    lm = lm[amp[lm] > ratio * floor]
    lm = lm[np.argsort(-amp[lm])]
    res = 1.0 / max(revs, 1e-9)
    peaks: list[float] = []
    for i in lm:
        k = float(orders[i])
        kr = round(k)
        if kr >= 1 and abs(k - kr) <= max(res, 0.05):
            k = float(kr)
        else:
            k = round(k, 2)
        if not any(abs(k - p) <= res for p in peaks):
            peaks.append(k)
        if len(peaks) >= max_peaks:
            break
    return peaks, floor


def analyse_orders(r: np.ndarray, theta: np.ndarray, variable: str, *, modulator: np.ndarray | None = None,
                   modulator_name: str = "", segment: np.ndarray | None = None,
                   ratio: float = 6.0, max_peaks: int = 6) -> OrderSpectrum:
    """Order spectrum and its lines for one (variable, modulator)."""
    orders, revs = order_grid(theta)
    if len(orders) == 0:
        return OrderSpectrum(variable, modulator_name, orders, np.zeros(0), 0.0, [], revs)
    x = r if modulator is None else r * modulator
    amp, se = order_spectrum(x, theta, orders, angle_weights(theta, segment), return_se=True)
    # lines on the amplitude in units of its own noise level (orders of unequal support), reported in N*m
    se0 = float(np.min(se)) if np.isfinite(se).any() else 1.0
    scale = np.where(np.isfinite(se), se / se0, np.inf)
    rel = np.where(np.isfinite(scale), amp / np.where(np.isfinite(scale), scale, 1.0), 0.0)
    peaks, floor = find_peaks(orders, rel, ratio=ratio, max_peaks=max_peaks, revs=revs)
    return OrderSpectrum(variable, modulator_name, orders, amp, floor, peaks, revs, scale)


def binned(x: np.ndarray, y: np.ndarray, bins: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Median of y in quantile bins of x: (bin centres, medians, counts)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < bins * 3:
        bins = max(2, len(x) // 3)
    if len(x) < 6:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    cnt = np.bincount(idx, minlength=len(edges) - 1)
    order = np.argsort(idx, kind="stable")
    splits = np.split(y[order], np.cumsum(cnt)[:-1])
    med = np.array([np.median(s) if len(s) else np.nan for s in splits])
    ctr = 0.5 * (edges[:-1] + edges[1:])
    return ctr, med, cnt


@dataclass
class BandLine:
    """An order proposed by :func:`band_line_scan`: its leave-one-block-out CV gain on the residual (share of the
    residual's SSE), the paired t of the per-block drops, the robust z of that gain among all orders' gains at the
    same speed, and the half-share speed v_b (rad/s; inf: no roll-off)."""
    order: float
    gain: float
    t: float
    z: float
    v_b: float
    revolutions: float = 0.0  # angle the rows travel, each row weighted by its share L, revolutions


#: a line search's order stands out when its CV gain's paired t >= this ...
BAND_LINE_T = 3.0
#: ... and its gain's robust z among the other orders' gains at the same speed >= this
BAND_LINE_Z = 5.0


def _rolled(c: np.ndarray, s: np.ndarray, x: np.ndarray | None, L: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """The pair cos, sin of an order's phase through a first-order roll-off at x = omega / v_b, L = 1 / (1 + x^2):
    [(cos + x sin) L, (sin - x cos) L], i.e. amplitude 1 / sqrt(1 + x^2) and phase lag atan(x) for any coefficients
    (x None: the plain pair)."""
    if x is None:
        return c, s
    return (c + x * s) * L, (s - x * c) * L


def _band_pair(theta: np.ndarray, omega: np.ndarray, k: float, v: float, seen: np.ndarray) -> tuple[np.ndarray, ...]:
    """The two columns of an order-k ripple through the roll-off at the half-share speed v (:func:`_rolled`; v inf:
    the plain pair), zero on the rows not ``seen``."""
    c, s = np.cos(k * theta) * seen, np.sin(k * theta) * seen
    if not np.isfinite(v):
        return _rolled(c, s, None, None)
    x = omega / v
    return _rolled(c, s, x, 1.0 / (1.0 + x * x))


def _band_scan(r, theta, omega, bi, nb, step, ks, sp):
    """CV gain, paired t, robust z and share-weighted revolutions travelled per (order, speed) of the pair of
    :func:`_band_pair` on the residual r."""
    rr = np.bincount(bi, r * r, nb)
    G = np.full((len(ks), len(sp)), np.nan)
    T = np.full((len(ks), len(sp)), np.nan)
    R = np.zeros((len(ks), len(sp)))
    # the roll-off per speed, computed once (as _band_pair does it)
    xl = []
    for v in sp:
        x = omega / v if np.isfinite(v) else None
        xl.append((x, None if x is None else 1.0 / (1.0 + x * x)))
    for i, k in enumerate(ks):
        # only the rows that sample the order enter its sums (the others' columns are zero: skipping them leaves every
        # per-block sum as it is; a fast log's high orders are seen by its slow rows only)
        idx = np.flatnonzero(k * step <= np.pi)
        if len(idx) < 10:
            continue
        full = len(idx) == len(r)
        th, st, bk, rk = (theta, step, bi, r) if full else (theta[idx], step[idx], bi[idx], r[idx])
        c, s = np.cos(k * th), np.sin(k * th)
        for jv, (x, L) in enumerate(xl):
            if x is not None and not full:
                x, L = x[idx], L[idx]
            R[i, jv] = float(np.sum(st if x is None else L * st) / (2 * np.pi))
            a1, a2 = _rolled(c, s, x, L)
            g11, g12, g22 = (np.bincount(bk, a1 * a1, nb), np.bincount(bk, a1 * a2, nb), np.bincount(bk, a2 * a2, nb))
            h1, h2 = np.bincount(bk, a1 * rk, nb), np.bincount(bk, a2 * rk, nb)
            # leave block j out: coefficients from the other blocks' sums, the SSE on block j from its own sums
            G11, G12, G22, H1, H2 = (g11.sum() - g11, g12.sum() - g12, g22.sum() - g22, h1.sum() - h1, h2.sum() - h2)
            det = G11 * G22 - G12 * G12
            good = det > 1e-12 * np.maximum(G11 * G22, 1e-300)
            det = np.where(good, det, 1.0)
            b1 = np.where(good, (G22 * H1 - G12 * H2) / det, 0.0)
            b2 = np.where(good, (G11 * H2 - G12 * H1) / det, 0.0)
            drop = 2 * (b1 * h1 + b2 * h2) - (b1 * b1 * g11 + 2 * b1 * b2 * g12 + b2 * b2 * g22)
            G[i, jv] = float(drop.sum() / rr.sum())
            sd = float(np.std(drop, ddof=1))
            T[i, jv] = float(drop.sum() / (sd * np.sqrt(nb))) if sd > 0 else (np.inf if drop.sum() > 0 else 0.0)
    # an order's gain against the other orders' at the same speed: most orders hold no line, so theirs are the null
    # of "a periodic function of theta fits the residual's other structure on these rows" (a Stribeck rise left on
    # the slow rows lets every high order gain there alike)
    with np.errstate(all="ignore"):
        med = np.nanmedian(G, 0)
        mad = 1.4826 * np.nanmedian(np.abs(G - med), 0)
    Z = (G - med) / np.where(mad > 0, mad, np.inf)
    return G, T, Z, R


def band_line_scan(r: np.ndarray, theta: np.ndarray, omega: np.ndarray, block: np.ndarray, *, k_max: float = 200.0,
                   speeds: np.ndarray | None = None, known: tuple[float, ...] | list[float] = (),
                   max_lines: int = 3, min_t: float = BAND_LINE_T, min_z: float = BAND_LINE_Z,
                   min_revolutions: float = LINE_REVOLUTIONS) -> tuple[list[BandLine], list[BandLine]]:
    """Integer orders of ``theta`` whose ripple, as a drive with a finite band shows it, lowers the residual's
    leave-one-block-out CV error: a regression line search for the lines the order spectrum does not see.

    A torque periodic in the motor angle is a disturbance at k |omega|; the logged torque carries it only where that
    frequency is within the drive's band, i.e. on the slow rows, and it fades as 1 / (1 + (omega / v_b)^2) beyond
    (``library._band_limited``). The order spectrum integrates over the angle travelled, which the fast rows
    dominate, and its grid ends where the slow rows stop covering two revolutions: a line at order 60 seen only below
    ~10 rad/s is not on it (hd_sim's default cogging, ``hdphm bench discover`` seed 100).

    Here every integer order up to ``k_max`` is fitted to ``r`` by least squares as the pair
    [(cos + x sin) L, (sin - x cos) L] (x = omega / v_b, L = 1 / (1 + x^2): a first-order response, amplitude
    1 / sqrt(1 + x^2) with a phase lag atan(x), not the band-limited candidate's magnitude-only share
    1 / (1 + x^2): a search shape, falling off beyond v_b as both do; the plain pair at v_b = inf) at each
    half-share speed in ``speeds``, rows that sample the order below two samples per period left out (its aliases),
    and scored by the leave-one-block-out CV SSE over ``block``'s blocks, from per-block Gram sums (the baseline is
    not refitted: a search, not a selection). Per order, the speed is the one with the largest CV gain among those at
    which the rows that carry the line travel ``min_revolutions`` (the spectrum's rule, ``LINE_REVOLUTIONS``: the
    angle a periodicity needs to be told from a trend), each row's angle step weighted by its share L (a line carried
    by the rows below 0.3 rad/s alone is the presliding regime's structure, not a periodicity: clean hysteretic-robot
    data at seed 17300). The order stands out when that gain's paired t >= ``min_t`` and its robust z among all
    orders' gains at the same speed >= ``min_z``. The search is a pursuit: the ``known``
    orders' plain pairs are projected out of ``r`` first (a strong line's leakage into the slow rows' fits of other
    orders is not a line), then the strongest order that stands out (largest z) is taken, its pair at its speed is
    projected out, and the search runs again, up to ``max_lines`` orders.

    Returns (the orders found, in the order taken; the first search's best per order, largest gain first, for the
    report). The orders found only join the candidate orders: discovery's selection admits or refuses them by its
    own CV and identification rules."""
    r = np.asarray(r, float)
    theta = np.asarray(theta, float)
    omega = np.asarray(omega, float)
    block = np.asarray(block)
    ok = np.isfinite(r) & np.isfinite(theta) & np.isfinite(omega)
    r, theta, omega, block = r[ok], theta[ok], omega[ok], block[ok]
    ub, bi = np.unique(block, return_inverse=True)
    nb = len(ub)
    if nb < 3 or len(r) < 10 or k_max < 1 or not np.any(r):
        return [], []
    # per-sample angle step: the smaller of the two neighbouring steps (a row next to a cut-out stretch keeps its own)
    d = np.abs(np.diff(theta))
    step = np.minimum(np.r_[d[:1], d], np.r_[d, d[-1:]]) if len(d) else np.zeros(len(theta))
    sp = [np.inf] + ([] if speeds is None else [float(v) for v in speeds if np.isfinite(v) and v > 0])
    ks = np.arange(1, int(np.floor(k_max)) + 1)
    cols = [c for k in known if np.isfinite(k) and k > 0 for c in _band_pair(theta, omega, float(k), np.inf, True)]
    taken: set[float] = {float(round(k)) for k in known if np.isfinite(k)}
    lines: list[BandLine] = []
    first: list[BandLine] = []
    while True:
        res = r
        if cols:
            A = np.column_stack(cols)
            res = r - A @ np.linalg.lstsq(A, r, rcond=None)[0]
        G, T, Z, R = _band_scan(res, theta, omega, bi, nb, step, ks, sp)
        best: list[BandLine] = []
        for i, k in enumerate(ks):
            # an order's speed is chosen among those at which its rows travel the revolutions a periodicity needs
            Gi = np.where(R[i] >= min_revolutions, G[i], np.nan)
            if not np.isfinite(Gi).any():
                continue
            jv = int(np.nanargmax(Gi))
            best.append(BandLine(float(k), float(G[i, jv]), float(T[i, jv]), float(Z[i, jv]), sp[jv], float(R[i, jv])))
        if not lines:  # the first search
            first = sorted(best, key=lambda b: -b.gain)
        out = [b for b in best if b.gain > 0 and b.t >= min_t and b.z >= min_z and b.order not in taken]
        if not out or len(lines) >= max_lines:
            break
        top = max(out, key=lambda b: b.z)
        lines.append(top)
        taken.add(top.order)
        cols += list(_band_pair(theta, omega, top.order, top.v_b, top.order * step <= np.pi))
    return lines, first
