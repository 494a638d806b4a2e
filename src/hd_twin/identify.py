"""Identification shared by the twin and discovery: separable least squares with identified shapes.

A model ``y ~ X(shape) @ coef`` is linear in ``coef`` and nonlinear in a few
shape parameters (friction transition width, Stribeck speed and exponent,
dead-zone width, ...). Variable projection: for any shape the coefficients are
the (weighted) least-squares solution, so only the shape is searched. The shape
is chosen by **cross-validated profile search** (leave-one-block-out over
contiguous time blocks, never interleaved samples): a coarse log grid, then a
bounded refinement (``scipy.optimize.minimize_scalar`` / ``minimize``). Its
uncertainty is the block jackknife of that choice; the coefficients' covariance
is the joint block jackknife (shape re-chosen without each block, coefficients
refitted at it: robust to coloured residuals and to blocks that differ, and it
carries the shape's uncertainty into the coefficients), or the classical OLS covariance when there are fewer than
3 blocks. A shape is *identified* only if the held-out error depends on it (the
CV profile is not flat), its optimum is inside the searched range, and its
jackknife standard deviation is below its size; otherwise the result says so
(``identified[name]`` and ``notes``) and the shape is set to the bound the data
are consistent with.

Public API (used by ``hd_twin`` and ``hd_ground.discovery``; never imports
``hd_sim`` or ``hd_ground``):

* :func:`derivative` -- Savitzky-Golay derivative designed at the measured rate.
* :func:`speed_noise_sigma` -- white-noise sigma of a measured speed (MAD of second differences).
* :func:`prepare_signals` -- one signal table from one or several files, with ``file``,
  ``block`` and the derivatives ``alpha_m`` / ``alpha_f``.
* :class:`Shape` -- a nonlinear parameter to search: name, bounds, log scale.
* :func:`fit_separable` -- the generic variable-projection fit -> :class:`SeparableFit`.
* :func:`vp_shape` -- least-squares refinement of a shape on the cross-validated residuals, with its
  block-robust sandwich uncertainty and a weak-identification flag -> :class:`ShapeVP`.
* :func:`presliding_state` -- the rate-independent (Dahl / LuGre bristle) friction or hysteresis state.
* :func:`hysteresis_state` -- the normalised Bouc-Wen state of a displacement, loop shape (n, phi) free
  (Dahl is n = 1, phi = 1).
* :func:`identify_torque_balance` -- the motor-side torque balance -> :class:`Identified`.
"""

from __future__ import annotations

import functools

from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

#: Default -3 dB point [Hz] of the derivative filter (cubic Savitzky-Golay); about a drive's speed-loop
#: bandwidth, and the window scales with the measured rate so the band stays put.
DERIV_CUTOFF_HZ = 40.0


class IdentifyError(ValueError):
    """Input the identification cannot work with (the message names the problem)."""


# ---------------------------------------------------------------------------
# signal preparation
# ---------------------------------------------------------------------------


def sg_window(fs: float, cutoff_hz: float = DERIV_CUTOFF_HZ, polyorder: int = 3) -> int:
    """Odd Savitzky-Golay window length for a first derivative with its -3 dB point at ``cutoff_hz``.

    Designed numerically at the sample rate ``fs``: the longest window whose derivative filter still has
    |H(f)| >= |j 2 pi f| / sqrt(2) at ``cutoff_hz`` (the ideal differentiator's gain, -3 dB), so a 200 Hz
    and a 2 kHz log get the same band. A pure function of its arguments, cached (the streaming twin asks for
    it on every call): ``fs`` is taken to 6 significant digits.
    """
    return _sg_window(float(f"{float(fs):.6g}"), float(cutoff_hz), int(polyorder))


@functools.lru_cache(maxsize=64)
def _sg_window(fs: float, cutoff_hz: float, polyorder: int) -> int:
    from scipy.signal import savgol_coeffs

    fc = min(max(cutoff_hz, 1e-6), 0.45 * fs)
    best = polyorder + 2 if polyorder % 2 else polyorder + 1  # smallest odd window > polyorder
    m = best // 2
    while 2 * m + 1 < 20 * fs / fc:
        w = 2 * m + 1
        c = savgol_coeffs(w, polyorder, deriv=1, delta=1.0 / fs, use="dot")
        k = np.arange(-m, m + 1)
        h = abs(np.sum(c * np.exp(-2j * np.pi * fc * k / fs)))
        if h < (2 * np.pi * fc) / np.sqrt(2):
            break
        best = w
        m += 1
    return best


def derivative(x: np.ndarray, t: np.ndarray, *, segment: np.ndarray | None = None,
               cutoff_hz: float = DERIV_CUTOFF_HZ, polyorder: int = 3) -> np.ndarray:
    """Time derivative of ``x`` [unit/s], Savitzky-Golay smoothed, per contiguous segment.

    The window is designed at each segment's median sample rate (:func:`sg_window`), so a 200 Hz and a
    2 kHz log get the same cut-off. Segments too short for the window use central differences.
    """
    x = np.asarray(x, float)
    t = np.asarray(t, float)
    seg = np.zeros(len(x), int) if segment is None else np.asarray(segment)
    out = np.full(len(x), np.nan)
    for s in np.unique(seg):
        idx = np.flatnonzero(seg == s)
        if len(idx) < 3:
            continue
        dt = float(np.median(np.diff(t[idx])))
        if not dt > 0:
            raise IdentifyError(f"time stamps do not increase in segment {s}")
        w = sg_window(1.0 / dt, cutoff_hz, polyorder)
        if len(idx) > w:
            out[idx] = _sg_derivative(x[idx], w, polyorder, dt)
        else:
            out[idx] = np.gradient(x[idx], t[idx])
    return out


@functools.lru_cache(maxsize=64)
def _sg_coefficients(w: int, polyorder: int, dt_key: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Savitzky-Golay first-derivative weights: the centre row and the left / right edge rows (each a
    fit of the first / last ``w`` samples evaluated at the edge positions, as ``savgol_filter``'s
    ``mode="interp"`` does with a polynomial fit per call)."""
    from scipy.signal import savgol_coeffs

    dt = float(dt_key)
    m = w // 2
    centre = savgol_coeffs(w, polyorder, deriv=1, delta=dt, use="dot")
    left = np.array([savgol_coeffs(w, polyorder, deriv=1, delta=dt, pos=k, use="dot") for k in range(m)])
    right = np.array([savgol_coeffs(w, polyorder, deriv=1, delta=dt, pos=k, use="dot") for k in range(w - m, w)])
    return centre, left, right


def _sg_derivative(x: np.ndarray, w: int, polyorder: int, dt: float) -> np.ndarray:
    """``savgol_filter(x, w, polyorder, deriv=1, delta=dt)`` (mode ``interp``) with cached weights: the
    streaming twin evaluates it on a short history at every sample, where the per-call edge fits cost
    ~1 ms."""
    centre, left, right = _sg_coefficients(int(w), int(polyorder), f"{float(dt):.12g}")
    m = w // 2
    out = np.empty(len(x))
    out[m:len(x) - m] = np.correlate(x, centre, mode="valid")
    out[:m] = left @ x[:w]
    out[len(x) - m:] = right @ x[-w:]
    return out


def speed_noise_sigma(omega: np.ndarray, segment: np.ndarray | None = None) -> float:
    """Robust white-noise sigma of a measured speed (MAD of second differences within segments).

    A second difference removes smooth motion (up to its curvature); white noise of sigma s gives a
    second difference of sigma sqrt(6) s.
    """
    omega = np.asarray(omega, float)
    d2 = omega[2:] - 2 * omega[1:-1] + omega[:-2]
    ok = np.isfinite(d2)
    if segment is not None:
        segment = np.asarray(segment)
        ok &= segment[2:] == segment[:-2]
    d2 = d2[ok]
    if len(d2) < 10:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def prepare_signals(signals: Mapping[str, np.ndarray] | Sequence[Mapping[str, np.ndarray]], *,
                    blocks_per_file: int = 4, cutoff_hz: float = DERIV_CUTOFF_HZ) -> dict[str, np.ndarray]:
    """One signal table from one file (dict) or several (list of dicts), finite rows only.

    Adds ``file`` (file index, kept if given), ``block`` (contiguous time blocks, ``blocks_per_file`` per
    file, the cross-validation folds), ``alpha_m`` = d omega_m/dt and ``alpha_f`` = d omega_f/dt when
    absent (:func:`derivative` per file and ``segment``). ``t`` is required.
    """
    parts = [signals] if isinstance(signals, Mapping) else list(signals)
    if not parts:
        raise IdentifyError("no signals given")
    if len(parts) == 1 and "file" in parts[0]:
        f = np.asarray(parts[0]["file"])
        parts = [{k: np.asarray(v)[f == i] for k, v in parts[0].items()} for i in np.unique(f)]
    tables = []
    for i, p in enumerate(parts):
        s = {k: np.asarray(v, float) for k, v in p.items() if np.ndim(v) == 1}
        if "t" not in s:
            raise IdentifyError(f"file {i}: no time stamps 't'")
        n = len(s["t"])
        for k, v in s.items():
            if len(v) != n:
                raise IdentifyError(f"file {i}: signal {k} has {len(v)} samples, 't' has {n}")
        seg = s.get("segment")
        for src, dst in (("omega_m", "alpha_m"), ("omega_f", "alpha_f")):
            if src in s and dst not in s:
                s[dst] = derivative(s[src], s["t"], segment=seg, cutoff_hz=cutoff_hz)
        frac = (s["t"] - s["t"][0]) / max(float(s["t"][-1] - s["t"][0]), 1e-12)
        s["block"] = np.minimum((frac * blocks_per_file).astype(int), blocks_per_file - 1) + i * blocks_per_file
        s["file"] = np.full(n, i, float)
        tables.append(s)
    keys = set.intersection(*(set(s) for s in tables))
    out = {k: np.concatenate([s[k] for s in tables]) for k in sorted(keys)}
    ok = np.ones(len(out["t"]), bool)
    for v in out.values():
        ok &= np.isfinite(v)
    out = {k: v[ok] for k, v in out.items()}
    out["block"] = out["block"].astype(int)
    out["file"] = out["file"].astype(int)
    return out


# ---------------------------------------------------------------------------
# block least squares
# ---------------------------------------------------------------------------


class BlockGram:
    """Per-block Gram matrices: leave-one-block-out least squares in O(blocks p^3).

    ``X`` (n, p), ``y`` (n,), ``block`` (n,) ints, optional ``weights`` (n,) >= 0.
    """

    def __init__(self, X: np.ndarray, y: np.ndarray, block: np.ndarray, weights: np.ndarray | None = None):
        if weights is not None:
            sw = np.sqrt(np.asarray(weights, float))
            X, y = X * sw[:, None], y * sw
        block = np.asarray(block)
        if len(block) > 1 and np.any(np.diff(block) < 0):
            o = np.argsort(block, kind="stable")
            X, y, block = X[o], y[o], block[o]
        self.scale = np.sqrt(np.mean(X**2, 0)) + 1e-300
        Xs = X / self.scale
        self.blocks, start = np.unique(block, return_index=True)
        sl = [slice(a, b) for a, b in zip(start, list(start[1:]) + [len(block)])]
        self.n = np.array([s.stop - s.start for s in sl])
        self.G = np.stack([Xs[s].T @ Xs[s] for s in sl])
        self.g = np.stack([Xs[s].T @ y[s] for s in sl])
        self.yy = np.array([y[s] @ y[s] for s in sl])

    def _solve(self, G, g):
        p = G.shape[-1]
        lam = 1e-10 * np.trace(G, axis1=-2, axis2=-1)[..., None, None] / max(p, 1)
        return np.linalg.solve(G + lam * np.eye(p), g[..., None])[..., 0]

    def coef(self, use: np.ndarray | None = None) -> np.ndarray:
        """Coefficients fitted on the blocks in ``use`` (bool per block; default all), unscaled units."""
        use = np.ones(len(self.blocks), bool) if use is None else use
        return self._solve(self.G[use].sum(0), self.g[use].sum(0)) / self.scale

    def sse(self, use: np.ndarray | None = None) -> float:
        """Training SSE on the blocks in ``use``."""
        use = np.ones(len(self.blocks), bool) if use is None else use
        G, g, yy = self.G[use].sum(0), self.g[use].sum(0), self.yy[use].sum()
        b = self._solve(G, g)
        return float(yy - 2 * b @ g + b @ G @ b)

    def cv_sse(self, use: np.ndarray | None = None) -> np.ndarray:
        """Held-out SSE of each block in ``use``, predicted from the other blocks in ``use`` (NaN elsewhere)."""
        use = np.ones(len(self.blocks), bool) if use is None else use
        Gt, gt = self.G[use].sum(0), self.g[use].sum(0)
        beta = self._solve(Gt[None] - self.G, gt[None] - self.g)
        out = self.yy - 2 * np.einsum("bi,bi->b", beta, self.g) + np.einsum("bi,bij,bj->b", beta, self.G, beta)
        out[~use] = np.nan
        return out

    def jackknife_cov(self) -> np.ndarray | None:
        """Block-jackknife covariance of the coefficients (unscaled units); None with < 3 blocks."""
        nb = len(self.blocks)
        if nb < 3:
            return None
        Gt, gt = self.G.sum(0), self.g.sum(0)
        B = self._solve(Gt[None] - self.G, gt[None] - self.g) / self.scale
        D = B - B.mean(0)
        return (nb - 1) / nb * (D.T @ D)


# ---------------------------------------------------------------------------
# separable fit with identified shapes
# ---------------------------------------------------------------------------


@dataclass
class Shape:
    """A nonlinear parameter searched by CV profile: ``lo < value < hi`` (log grid when ``log``)."""

    name: str
    lo: float
    hi: float
    log: bool = True
    n_grid: int = 12

    def grid(self) -> np.ndarray:
        return np.geomspace(self.lo, self.hi, self.n_grid) if self.log else np.linspace(self.lo, self.hi, self.n_grid)

    def to_u(self, v):
        return np.log(v) if self.log else np.asarray(v, float)

    def from_u(self, u):
        return float(np.exp(u)) if self.log else float(u)


@dataclass
class SeparableFit:
    """Result of :func:`fit_separable` (all in the units of ``y`` and the columns)."""

    names: list[str]
    coef: np.ndarray
    cov: np.ndarray
    shape: dict[str, float]
    shape_sd: dict[str, float]
    identified: dict[str, bool]
    cv_rmse: float  # leave-one-block-out RMSE at the chosen shape
    rmse: float  # training RMSE at the chosen shape
    profile: dict[str, list]  # name -> [[value, cv_rmse], ...] along the grid (others at their optimum)
    notes: list[str] = field(default_factory=list)


def fit_separable(y: np.ndarray, design: Callable[[dict], np.ndarray], names: list[str], block: np.ndarray,
                  shapes: Sequence[Shape] = (), *, weights: np.ndarray | None = None,
                  flat_tol: float = 1e-3, jackknife: bool = True, positive: Sequence[int] = (),
                  max_jk: int = 10) -> SeparableFit:
    """Variable projection: ``y ~ design(shape) @ coef`` with the shape chosen by CV profile search.

    ``design(shape_dict)`` returns the (n, len(names)) column matrix for the given shape values.
    ``block`` gives the cross-validation folds (contiguous time blocks, >= 3 for CV and jackknife).
    A shape is flagged unidentified (``identified[name] = False``, a note says why) when the CV RMSE
    over its searched range varies by less than ``flat_tol`` (relative), when the optimum sits on a
    bound (within 2 % of the searched range: the data only bound it; the bound is kept), or when its
    jackknife SD exceeds its own size (log shapes: SD of the log value > 1). Columns listed in
    ``positive`` must get a positive coefficient (physics): shapes where they do not are not chosen.
    The jackknife leaves out one of at most ``max_jk`` groups of neighbouring blocks at a time.
    The grid's best point is refined within its cell; joint shapes (two or more) are refined also from each of
    the grid's lowest local minima across the searched range (:func:`_refine_from_grid_minima`), and the lowest
    CV error wins (shapes that trade off along a valley crossing cells diagonally; issue 10, seventeenth pass).
    """
    y = np.asarray(y, float)
    block = np.asarray(block)
    nb = len(np.unique(block))
    notes: list[str] = []
    shapes = list(shapes)
    cache: dict[tuple, BlockGram] = {}

    def gram(vals: tuple) -> BlockGram:
        if vals not in cache:
            if len(cache) > 256:
                cache.clear()
            X = design(dict(zip([s.name for s in shapes], vals)))
            cache[vals] = BlockGram(X, y, block, weights)
        return cache[vals]

    penalty = 10.0 * float(np.sum(np.asarray(y, float) ** 2)) + 1.0

    def cv_obj(vals: tuple, use: np.ndarray | None = None) -> float:
        gm = gram(vals)
        if positive and np.any(gm.coef(use)[list(positive)] <= 0):
            return penalty
        if nb >= 3:
            return float(np.nansum(gm.cv_sse(use)))
        return gm.sse(use)

    def optimise(use: np.ndarray | None, start: tuple | None) -> tuple[tuple, float, dict]:
        if not shapes:
            return (), cv_obj((), use), {}
        grids = [s.grid() for s in shapes]
        if start is None:
            mesh = np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(shapes), -1).T
            vals = [cv_obj(tuple(float(v) for v in row), use) for row in mesh]
            k = int(np.argmin(vals))
            best = tuple(float(v) for v in mesh[k])
            prof = {}
            vv = np.array(vals).reshape([len(g) for g in grids])
            for i, s in enumerate(shapes):
                ax = tuple(j for j in range(len(shapes)) if j != i)
                prof[s.name] = np.min(vv, axis=ax) if ax else vv
        else:
            best, prof = start, {}
        from scipy.optimize import minimize, minimize_scalar

        # bounded refinement within one grid cell (in log for log shapes; for one shape a local minimum of the
        # grid brackets a local minimum of the CV error within one cell on either side)
        lo = [max(s.to_u(s.lo), s.to_u(b) - _cell(s)) for s, b in zip(shapes, best)]
        hi = [min(s.to_u(s.hi), s.to_u(b) + _cell(s)) for s, b in zip(shapes, best)]

        def f(u):
            u = np.clip(np.atleast_1d(u), lo, hi)
            return cv_obj(tuple(s.from_u(ui) for s, ui in zip(shapes, u)), use)

        if len(shapes) == 1:
            r = minimize_scalar(f, bounds=(lo[0], hi[0]), method="bounded", options={"xatol": 1e-3})
            u = np.atleast_1d(r.x)
            fu = float(r.fun)
        else:
            r = minimize(f, [s.to_u(b) for s, b in zip(shapes, best)], method="Nelder-Mead",
                         bounds=list(zip(lo, hi)), options={"xatol": 1e-3, "fatol": 1e-9, "maxfev": (60 if start is None else 25) * len(shapes)})
            u, fu = np.clip(r.x, lo, hi), float(r.fun)
        f0 = cv_obj(best, use)
        if fu < f0:
            best = tuple(s.from_u(ui) for s, ui in zip(shapes, u))
            f0 = fu
        if start is None and len(shapes) > 1:
            # joint shapes: the grid's best point need not lie in the basin of the lowest CV error (the shapes
            # trade off along curved valleys that run diagonally across grid cells, e.g. Stribeck's omega_s,
            # delta and width), so the refinement confined to its cell can stop on the cell's edge, and the best
            # grid point can sit in a secondary basin: refined also from each of the grid's lowest local minima
            # (:func:`_grid_minima`) within the whole searched range; the lowest CV error of all wins
            b2, f2 = _refine_from_grid_minima(shapes, grids, vv, lambda v: cv_obj(v, use), penalty)
            if f2 < f0:
                best, f0 = b2, f2
        return best, f0, prof

    best, fbest, prof = optimise(None, None)
    g = gram(best)
    coef = g.coef()
    n = len(y)
    rmse = float(np.sqrt(max(g.sse(), 0.0) / n))
    cv_rmse = float(np.sqrt(max(fbest, 0.0) / n))
    cov = g.jackknife_cov()
    if cov is None:
        X = design(dict(zip([s.name for s in shapes], best)))
        w = np.ones(n) if weights is None else np.asarray(weights, float)
        XtWX = X.T @ (X * w[:, None])
        dof = max(n - X.shape[1], 1)
        cov = rmse**2 * n / dof * np.linalg.pinv(XtWX)
        notes.append(f"fewer than 3 blocks ({nb}): classical OLS covariance (assumes white residuals)")
    shape = {s.name: float(v) for s, v in zip(shapes, best)}
    shape_sd: dict[str, float] = {}
    identified: dict[str, bool] = {}
    for i, s in enumerate(shapes):
        pr = np.asarray(prof[s.name], float)
        identified[s.name] = True
        pr = pr[pr < penalty]
        rng = (np.max(pr) - np.min(pr)) / max(np.min(pr), 1e-300) if len(pr) else 0.0
        if fbest >= penalty:
            identified[s.name] = False
            notes.append(f"{s.name}: no value in {s.lo:.3g}..{s.hi:.3g} gives the required positive coefficient")
        elif rng < flat_tol:
            identified[s.name] = False
            notes.append(f"{s.name}: the held-out error does not depend on it over {s.lo:.3g}..{s.hi:.3g} "
                         f"(CV profile varies by {rng:.1e}); not identified")
        else:
            span = s.to_u(s.hi) - s.to_u(s.lo)
            pos = (s.to_u(best[i]) - s.to_u(s.lo)) / span
            at = "lower" if pos < 0.02 else ("upper" if pos > 0.98 else None)
            if at is not None:
                identified[s.name] = False
                notes.append(f"{s.name}: the data only bound it (optimum at the {at} bound "
                             f"{best[i]:.3g} of the searched range); kept at that bound")
        shape_sd[s.name] = float("nan")
    if shapes and jackknife and nb >= 3:
        blocks = np.unique(block)
        # jackknife groups: at most ``max_jk`` groups of neighbouring blocks (each left out in turn)
        grp = np.minimum((np.arange(len(blocks)) * min(max_jk, len(blocks))) // len(blocks), max_jk - 1)
        ng = int(grp.max()) + 1
        jk, jb = [], []
        for b in range(ng):
            use = grp != b
            v, _, _ = optimise(use, best)
            jk.append([s.to_u(x) for s, x in zip(shapes, v)])
            jb.append(gram(v).coef(use))
        jk, jb = np.asarray(jk), np.asarray(jb)
        # joint jackknife: the coefficients' covariance includes the uncertainty of the shape they depend on
        d = jb - jb.mean(0)
        cov = (ng - 1) / ng * (d.T @ d)
        sd_u = np.sqrt((ng - 1) / ng * np.sum((jk - jk.mean(0)) ** 2, 0))
        for i, s in enumerate(shapes):
            shape_sd[s.name] = float(sd_u[i] * best[i]) if s.log else float(sd_u[i])
            too_wide = sd_u[i] > 1.0 if s.log else sd_u[i] > abs(best[i])
            if identified[s.name] and too_wide:
                identified[s.name] = False
                notes.append(f"{s.name} = {best[i]:.3g} +- {shape_sd[s.name]:.2g} (block jackknife): "
                             "uncertain by more than its own size; not identified")
    profile = {s.name: [[float(v), float(np.sqrt(max(p, 0) / n))] for v, p in zip(s.grid(), prof[s.name])]
               for s in shapes}
    return SeparableFit(list(names), coef, cov, shape, shape_sd, identified, cv_rmse, rmse, profile, notes)


def _cell(s: Shape) -> float:
    return (s.to_u(s.hi) - s.to_u(s.lo)) / max(s.n_grid - 1, 1)


#: Local minima of the shape grid refined by :func:`fit_separable` for joint shapes (the lowest CV errors first).
MAX_GRID_STARTS = 3


def _grid_minima(vv: np.ndarray, penalty: float, k: int = MAX_GRID_STARTS) -> list[tuple]:
    """Indices of the ``k`` lowest local minima of the CV error on the shape grid ``vv`` (a point no higher than
    its neighbours, diagonals included; points at the penalty, i.e. without the required sign, excluded)."""
    from scipy.ndimage import minimum_filter

    v = np.where(np.isfinite(vv) & (vv < penalty), vv, np.inf)
    loc = np.argwhere((v <= minimum_filter(v, size=3, mode="nearest")) & np.isfinite(v))
    order = np.argsort([v[tuple(i)] for i in loc], kind="stable")
    return [tuple(int(j) for j in loc[i]) for i in order[:k]]


def _refine_from_grid_minima(shapes, grids, vv, obj, penalty):
    """Nelder-Mead on the CV error from each of the grid's lowest local minima (:func:`_grid_minima`), bounded by
    the searched range, with a first simplex of half a grid cell per shape (search coordinates); the lowest CV
    error wins (the grid's best point when no refinement improves on it). Returns (shape values, CV SSE)."""
    from scipy.optimize import minimize

    lo = [s.to_u(s.lo) for s in shapes]
    hi = [s.to_u(s.hi) for s in shapes]

    def f(u):
        u = np.clip(np.asarray(u, float), lo, hi)
        return obj(tuple(s.from_u(ui) for s, ui in zip(shapes, u)))

    k0 = np.unravel_index(int(np.argmin(vv)), vv.shape)
    best = tuple(float(g[i]) for g, i in zip(grids, k0))
    fbest = obj(best)
    for ijk in _grid_minima(vv, penalty):
        u0 = np.array([s.to_u(g[i]) for s, g, i in zip(shapes, grids, ijk)], float)
        step = np.array([0.5 * _cell(s) for s in shapes])
        simplex = np.vstack([u0] + [np.clip(u0 + np.eye(len(shapes))[i] * step[i] * (1 if u0[i] + step[i] <= hi[i]
                                                                                        else -1), lo, hi)
                                    for i in range(len(shapes))])
        r = minimize(f, u0, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                     options={"xatol": 1e-3, "fatol": 1e-9, "maxfev": 100 * len(shapes), "initial_simplex": simplex})
        u = np.clip(r.x, lo, hi)
        fu = f(u)
        if fu < fbest:
            best, fbest = tuple(s.from_u(ui) for s, ui in zip(shapes, u)), fu
    return best, fbest


# ---------------------------------------------------------------------------
# variable projection on the cross-validated residuals: refinement and sandwich uncertainty
# ---------------------------------------------------------------------------


@dataclass
class ShapeVP:
    """Result of :func:`vp_shape` (shape values in their own units; ``log_se`` in e-folds for log shapes)."""

    shape: dict[str, float]  # the least-squares optimum of the CV residuals (from ``start``)
    se: dict[str, float]  # sandwich standard error (value units; log shapes: value x log_se)
    log_se: dict[str, float]  # standard error in the search coordinate (log for log shapes)
    corr: np.ndarray  # correlation matrix of the shape parameters (search coordinates)
    weak: list[str]  # shapes whose standard error exceeds their size (or whose curvature vanishes)
    cv_rmse: float  # leave-one-block-out RMSE at ``shape``
    cv_rmse_start: float  # ... at ``start``
    notes: list[str] = field(default_factory=list)


def scaled_lstsq(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares with every column scaled to unit RMS first: columns of a physical model differ by many orders of
    magnitude (a twist ~1e-3 rad, its cube ~1e-9), and ``lstsq``'s rank cut-off, relative to the largest singular
    value, would otherwise drop the small ones."""
    scale = np.sqrt(np.mean(X**2, 0)) + 1e-300
    beta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    return beta / scale


def cv_residuals(y: np.ndarray, X: np.ndarray, block: np.ndarray) -> np.ndarray:
    """Leave-one-block-out residuals: each row predicted by the least-squares fit on the other blocks."""
    y = np.asarray(y, float)
    block = np.asarray(block)
    scale = np.sqrt(np.mean(X**2, 0)) + 1e-300
    Xs = X / scale
    blocks, inv = np.unique(block, return_inverse=True)
    # per-block sums of the products (rows grouped by block: reduceat over the sorted order)
    order = np.argsort(inv, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(inv[order]) != 0])
    Xo = Xs[order]
    G = np.add.reduceat(Xo[:, :, None] * Xo[:, None, :], starts, axis=0)
    g = np.add.reduceat(Xo * y[order][:, None], starts, axis=0)
    Gt, gt = G.sum(0), g.sum(0)
    p = X.shape[1]
    lam = 1e-10 * np.trace(Gt) / max(p, 1)
    B = np.linalg.solve(Gt[None] - G + lam * np.eye(p)[None], (gt[None] - g)[..., None])[..., 0]
    return y - np.einsum("ij,ij->i", Xs, B[inv])


def vp_shape(y: np.ndarray, design: Callable[[dict], np.ndarray], block: np.ndarray, shapes: Sequence[Shape],
             start: Mapping[str, float], *, refine: bool = True, max_nfev: int = 60) -> ShapeVP:
    """Variable projection on the cross-validated residual vector, with a block-robust sandwich covariance.

    The coefficients are projected out (least squares on the other blocks for every row: the stacked
    leave-one-block-out residual vector r(u), u the shapes in their search coordinates, log for log
    shapes); ``scipy.optimize.least_squares`` minimises ||r(u)||^2 from ``start`` within the shapes'
    bounds (``refine``), and the uncertainty of u is the sandwich A^-1 B A^-1 of that M-estimator, with
    A = J^T J (J the Jacobian of r, central differences) and B = nb/(nb-1) sum_b (J_b^T r_b)(J_b^T r_b)^T over
    the blocks (robust to residuals correlated within a block and to blocks that differ). A shape whose
    standard error exceeds its own size (log shapes: more than one e-fold; linear shapes: more than
    |value|), along which the CV residuals do not change at all, or whose refined optimum lies on a bound
    of its searched range (within 2 %, the profile search's rule: a degenerate optimum the data only bound),
    is reported ``weak``: weakly identified by these data, whatever value the search returned. Unlike the block jackknife of the profile search,
    whose refits start from the full-data optimum, this sees flat directions of the CV surface.
    """
    from scipy.optimize import least_squares

    shapes = list(shapes)
    names = [s.name for s in shapes]
    y = np.asarray(y, float)
    block = np.asarray(block)
    lo = np.array([s.to_u(s.lo) for s in shapes], float)
    hi = np.array([s.to_u(s.hi) for s in shapes], float)
    u0 = np.clip(np.array([s.to_u(start[n]) for s, n in zip(shapes, names)], float), lo, hi)

    def shape_of(u):
        return {s.name: s.from_u(ui) for s, ui in zip(shapes, u)}

    def res(u):
        return cv_residuals(y, design(shape_of(u)), block)

    n = len(y)
    r0 = res(u0)
    cv0 = float(np.sqrt(np.mean(r0**2)))
    notes: list[str] = []
    u, r = u0, r0
    if refine and shapes:
        inside = (lo + 1e-9 < u0) & (u0 < hi - 1e-9)
        lo_, hi_ = np.where(inside, lo, u0 - 1e-9), np.where(inside, hi, u0 + 1e-9)  # a bound optimum stays
        sol = least_squares(res, u0, bounds=(lo_, hi_), diff_step=1e-3, max_nfev=max_nfev, x_scale=1.0)
        if float(np.sum(sol.fun**2)) < float(np.sum(r0**2)):
            u, r = np.asarray(sol.x, float), sol.fun
    # Jacobian of the CV residual vector at u (central differences in the search coordinates)
    h = 1e-3 * np.maximum(1.0, np.abs(u))
    J = np.empty((n, len(shapes)))
    for i in range(len(shapes)):
        up, um = u.copy(), u.copy()
        up[i] += h[i]
        um[i] -= h[i]
        J[:, i] = (res(up) - res(um)) / (2 * h[i])
    blocks, inv = np.unique(block, return_inverse=True)
    nb = len(blocks)
    S = np.zeros((nb, len(shapes)))
    np.add.at(S, inv, J * r[:, None])  # per-block score J_b^T r_b
    A = J.T @ J
    Bm = nb / max(nb - 1, 1) * (S.T @ S)
    weak: list[str] = []
    a_diag = np.diag(A)
    if np.any(a_diag <= 0):
        for i in np.flatnonzero(a_diag <= 0):
            weak.append(names[i])
            notes.append(f"{names[i]}: the cross-validated residuals do not depend on it; not identified")
    Ai = np.linalg.pinv(A, rcond=1e-12)
    C = Ai @ Bm @ Ai
    sd_u = np.sqrt(np.maximum(np.diag(C), 0.0))
    dd = np.where(sd_u > 0, sd_u, 1.0)
    corr = C / np.outer(dd, dd)
    shape = shape_of(u)
    se, log_se = {}, {}
    for i, s in enumerate(shapes):
        pos = (u[i] - lo[i]) / max(hi[i] - lo[i], 1e-300)
        if refine and (pos < 0.02 or pos > 0.98) and s.name not in weak:
            # the same rule as the profile search: an optimum on a bound is only bounded by the data
            weak.append(s.name)
            notes.append(f"{s.name}: the least-squares optimum of the cross-validated residuals is at the "
                         f"{'lower' if pos < 0.02 else 'upper'} bound {shape[s.name]:.3g} of the searched range "
                         "(a degenerate optimum): weakly identified")
        log_se[s.name] = float(sd_u[i])
        se[s.name] = float(sd_u[i] * shape[s.name]) if s.log else float(sd_u[i])
        too_wide = sd_u[i] > 1.0 if s.log else sd_u[i] > abs(shape[s.name])
        if too_wide and s.name not in weak:
            weak.append(s.name)
            notes.append(f"{s.name} = {shape[s.name]:.3g}: sandwich standard error "
                         + (f"{sd_u[i]:.2g} e-folds" if s.log else f"{sd_u[i]:.2g}")
                         + " (variable projection on the cross-validated residuals): weakly identified")
    return ShapeVP(shape, se, log_se, corr, weak, float(np.sqrt(np.mean(r**2))), cv0, notes)


# ---------------------------------------------------------------------------
# rate-independent friction / hysteresis state (Dahl; LuGre's bristle state at constant g)
# ---------------------------------------------------------------------------


def presliding_state(x: np.ndarray, distance: float, segment: np.ndarray | None = None) -> np.ndarray:
    """Normalised Dahl state s in [-1, 1] driven by the displacement ``x`` (time-ordered samples).

    ds/dx = (sgn(dx) - s) / distance: after a reversal the state leaves its old level and approaches the
    new direction's +-1 exponentially with the *travel* since the reversal, over the pre-sliding distance
    ``distance`` (same unit as x). This is Dahl's friction model and LuGre's bristle state z sigma0 / g
    when g is constant and the bristle damping is small (Canudas de Wit et al. 1995); on a twist it is the
    Bouc-Wen hysteresis state with n = 1, gamma = 0. Rate independent: the state depends on the path,
    not on the speed, so a friction torque T_C s passes through zero over a travel, not over a speed band
    as tanh(omega / eps) does. Exact for piecewise-monotone x between samples (increments are applied
    as one exponential step each); it restarts at 0 at each new ``segment`` (no travel history there).
    """
    x = np.asarray(x, float)
    n = len(x)
    out = np.zeros(n)
    if n == 0:
        return out
    d = float(distance)
    if not d > 0:
        raise IdentifyError(f"presliding_state: distance must be > 0 (got {distance})")
    seg = np.zeros(n, int) if segment is None else np.asarray(segment)
    dx = np.diff(x, prepend=x[0])
    start = np.r_[True, seg[1:] != seg[:-1]]
    dx[start] = 0.0
    # one exponential step per sample (a plain loop over Python floats: ~0.1 s per 200k samples)
    decay = np.exp(-np.abs(dx) / d).tolist()
    direction = np.sign(dx).tolist()
    restart = start.tolist()
    o = [0.0] * n
    z = 0.0
    for i in range(n):
        if restart[i]:
            z = 0.0
        else:
            r = direction[i]
            if r != 0.0:  # a zero increment: no travel, no change
                z = r + (z - r) * decay[i]
        o[i] = z
    out[:] = o
    return out


#: Search ranges of the Bouc-Wen loop shape (:func:`hysteresis_state`): the sharpness exponent n and the unloading
#: parameter phi = (beta - gamma) / (beta + gamma). phi >= 0 is Bouc-Wen's passivity condition (beta >= |gamma|);
#: the range reaches below it so that a loop with linear unloading (phi = 0, beta = gamma) is inside, not on a bound.
BW_N_RANGE = (0.4, 5.0)
BW_PHI_RANGE = (-0.6, 3.0)


@functools.lru_cache(maxsize=64)
def _bw_flow(n: float, phi: float, n_grid: int = 20001) -> tuple[np.ndarray, np.ndarray]:
    """Flow of the normalised Bouc-Wen state under increasing displacement: (u, s) on a grid, s(0) = -1.

    ds/du = 1 - |s|^n for s >= 0 (loading) and 1 + phi |s|^n for s < 0 (unloading), u the travel in units of the
    distance. Autonomous, so a state s0 moved by a travel du is S(U(s0) + du) with U the inverse of S. U is the
    quadrature of 1 / (ds/du) (cumulative trapezoid): on a uniform grid of s in [-1, 0], and in t = -ln(1 - s) on
    [0, 1), where the integrand e^-t / (1 - (1 - e^-t)^n) stays bounded (-> 1/n) up to 1 - s = e^-28.
    """
    s1 = np.linspace(-1.0, 0.0, n_grid)
    f1 = 1.0 / (1.0 + phi * np.abs(s1) ** n)
    u1 = np.r_[0.0, np.cumsum(0.5 * (f1[1:] + f1[:-1]) * np.diff(s1))]
    t = np.linspace(0.0, 28.0, n_grid)
    e = np.exp(-t)
    s2 = 1.0 - e
    with np.errstate(divide="ignore", invalid="ignore"):
        f2 = e / (1.0 - s2**n)
    f2[0] = 1.0  # s = 0: ds/du = 1
    u2 = u1[-1] + np.r_[0.0, np.cumsum(0.5 * (f2[1:] + f2[:-1]) * np.diff(t))]
    u, st = np.r_[u1, u2[1:]], np.r_[s1, s2[1:]]
    keep = np.r_[True, (np.diff(st) > 0) & (np.diff(u) > 0)]
    return u[keep], st[keep]


@functools.lru_cache(maxsize=64)
def _bw_tables(n: float, phi: float, m: int = 50001) -> tuple[list, list, float, float]:
    """Uniform-grid tables of the flow (U on s in [-1, 1], S on u in [0, u_max]) for the sequential loop."""
    u_t, s_t = _bw_flow(n, phi)
    s_g = np.linspace(-1.0, 1.0, m)
    u_g = np.linspace(0.0, float(u_t[-1]), m)
    U = np.interp(s_g, s_t, u_t)  # beyond the table's last state (within 1e-12 of 1): its travel
    S = np.interp(u_g, u_t, s_t)
    return U.tolist(), S.tolist(), (m - 1) / 2.0, (m - 1) / float(u_t[-1])


def hysteresis_state(x: np.ndarray, distance: float, n: float = 1.0, phi: float = 1.0,
                     segment: np.ndarray | None = None) -> np.ndarray:
    """Normalised Bouc-Wen hysteresis state s in [-1, 1] driven by the displacement ``x`` (time-ordered samples).

    Bouc-Wen, z' = A x' - beta |x'| |z|^(n-1) z - gamma x' |z|^n, normalised by its saturation z_max =
    (A / (beta + gamma))^(1/n) and with travel measured in d = z_max / A (``distance``, unit of x):
    ds/dx = [1 - |s|^n] / d while |s| grows (loading) and [1 + phi |s|^n] / d while it shrinks (unloading), phi =
    (beta - gamma) / (beta + gamma). The loop's shape is (n, phi): n the sharpness of the yield, phi how the state
    leaves saturation after a reversal (phi = 1: exponentially, Dahl / LuGre's bristle state, identical to
    :func:`presliding_state` at n = 1; phi = 0: linearly, beta = gamma; phi > 1: faster). Rate independent and
    exact for piecewise-monotone x between samples: within a monotone run the state is the flow map of the travel
    since the run began (:func:`_bw_flow`, tabulated once per shape), so only the reversals are a sequential loop.
    Restarts at 0 at each new ``segment``. Requires ``distance`` > 0, n > 0, phi > -1.
    """
    x = np.asarray(x, float)
    n_s = len(x)
    out = np.zeros(n_s)
    d = float(distance)
    if not d > 0 or not n > 0 or not phi > -1:
        raise IdentifyError(f"hysteresis_state: need distance > 0, n > 0, phi > -1 (got {distance}, {n}, {phi})")
    if n_s == 0:
        return out
    seg = np.zeros(n_s, int) if segment is None else np.asarray(segment)
    dx = np.diff(x, prepend=x[0])
    start = np.r_[True, seg[1:] != seg[:-1]]
    dx[start] = 0.0
    dx[~np.isfinite(dx)] = 0.0
    mv = np.flatnonzero(dx != 0)  # the samples that move the state
    if len(mv) == 0:
        return out
    r = np.sign(dx[mv])
    sg = seg[mv]
    new_run = np.r_[True, (r[1:] != r[:-1]) | (sg[1:] != sg[:-1])]
    run = np.cumsum(new_run) - 1
    first = np.flatnonzero(new_run)
    trav = np.abs(dx[mv]) / d
    cs = np.cumsum(trav)
    base = (cs - trav)[first]  # travel before each run
    cum = cs - base[run]  # travel since the run began (inclusive)
    total = np.r_[cum[first[1:] - 1], cum[-1]]
    u_t, s_t = _bw_flow(float(n), float(phi))
    Ug, Sg, inv_ds, inv_du = _bw_tables(float(n), float(phi))
    mU, mS = len(Ug) - 1, len(Sg) - 1
    u_last, s_last = Ug[-1], Sg[-1]
    rr, tot = r[first].tolist(), total.tolist()
    reset = np.r_[True, sg[first][1:] != sg[first][:-1]].tolist()
    u0 = [0.0] * len(first)
    s_prev = 0.0
    for k in range(len(first)):  # the one sequential part: the state each run starts from
        if reset[k]:  # a new segment: no travel history there
            s_prev = 0.0
        rk = rr[k]
        p = (rk * s_prev + 1.0) * inv_ds
        j = int(p)
        u = u_last if j >= mU else Ug[j] + (p - j) * (Ug[j + 1] - Ug[j])
        u0[k] = u
        q = (u + tot[k]) * inv_du
        j = int(q)
        s_prev = rk * (s_last if j >= mS else Sg[j] + (q - j) * (Sg[j + 1] - Sg[j]))
    u0 = np.asarray(u0)
    vals = r * np.interp(u0[run] + cum, u_t, s_t)
    # hold the state between moves; 0 before the first move of a segment
    last = np.full(n_s, -1)
    last[mv] = np.arange(len(mv))
    last = np.maximum.accumulate(last)
    ok = last >= 0
    held = np.zeros(n_s)
    held[ok] = vals[last[ok]]
    same = np.zeros(n_s, bool)
    same[ok] = seg[mv[last[ok]]] == seg[ok]
    out[same] = held[same]
    return out


# ---------------------------------------------------------------------------
# the torque balance
# ---------------------------------------------------------------------------


def coulomb_shape(omega: np.ndarray, width: float) -> np.ndarray:
    """Smooth Coulomb transition through zero speed: tanh(omega / width) [-]."""
    return np.tanh(np.asarray(omega, float) / max(width, 1e-12))


#: column name -> (signals, shape) -> array. The torque balance's regressors, one place.
COLUMNS: dict[str, Callable[[Mapping[str, np.ndarray], Mapping[str, float]], np.ndarray]] = {
    "tau_m": lambda s, sh: s["tau_m"],
    "Q_red": lambda s, sh: s["Q_red"],
    "alpha_m": lambda s, sh: s["alpha_m"],
    "coulomb": lambda s, sh: coulomb_shape(s["omega_m"], sh["width"]),
    "omega_m": lambda s, sh: s["omega_m"],
    "const": lambda s, sh: np.ones(len(s["omega_m"])),
}

#: physical reading of each coefficient, per target
MEANING = {
    "Q_red": {"tau_m": "N eta (gear ratio x efficiency)", "alpha_m": "-N eta J_eq", "coulomb": "-N eta T_C",
              "omega_m": "-N eta b", "const": "output-side offset"},
    "tau_m": {"Q_red": "1 / (N eta)", "alpha_m": "J_eq", "coulomb": "T_C", "omega_m": "b",
              "const": "motor-side offset"},
}


@dataclass
class Identified:
    """An identified torque balance: ``target ~ sum coef_i * column_i(signals; shape)``.

    ``names`` column names (keys of :data:`COLUMNS`), ``coef`` (p,), ``cov`` (p, p) block-jackknife
    covariance, ``shape`` {"width": rad/s}, ``shape_sd`` its SD, ``identified`` per shape, ``notes``
    (identifiability statements, what was done), ``target``, ``cv_rmse`` / ``rmse`` [target unit],
    ``cutoff_hz`` of the derivative filter (``predict`` differentiates the same way).
    """

    target: str
    names: list[str]
    coef: np.ndarray
    cov: np.ndarray
    shape: dict[str, float]
    shape_sd: dict[str, float]
    identified: dict[str, bool]
    notes: list[str]
    cv_rmse: float = float("nan")
    rmse: float = float("nan")
    cutoff_hz: float = DERIV_CUTOFF_HZ

    @property
    def sd(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    def columns(self, signals: Mapping[str, np.ndarray]) -> np.ndarray:
        s = dict(signals)
        if "alpha_m" in self.names and "alpha_m" not in s:
            if "t" not in s:
                raise IdentifyError("predict needs 't' (or 'alpha_m') to differentiate omega_m")
            s["alpha_m"] = derivative(s["omega_m"], s["t"], segment=s.get("segment"), cutoff_hz=self.cutoff_hz)
        return np.stack([np.asarray(COLUMNS[n](s, self.shape), float) for n in self.names], 1)

    def predict(self, signals: Mapping[str, np.ndarray]) -> np.ndarray:
        """The model's ``target`` for ``signals`` (one file: a dict of arrays with ``t`` or ``alpha_m``)."""
        return self.columns(signals) @ self.coef

    def to_dict(self) -> dict:
        return {"format": "hdphm-identified/1", "target": self.target, "names": list(self.names),
                "coef": [float(c) for c in self.coef], "cov": np.asarray(self.cov, float).tolist(),
                "shape": dict(self.shape), "shape_sd": dict(self.shape_sd), "identified": dict(self.identified),
                "notes": list(self.notes), "cv_rmse": self.cv_rmse, "rmse": self.rmse, "cutoff_hz": self.cutoff_hz,
                "meaning": {n: MEANING.get(self.target, {}).get(n, "") for n in self.names}}

    @classmethod
    def from_dict(cls, d: Mapping) -> "Identified":
        if d.get("format") != "hdphm-identified/1":
            raise IdentifyError(f"not an identified torque balance (format {d.get('format')!r})")
        unknown = [n for n in d["names"] if n not in COLUMNS]
        if unknown:
            raise IdentifyError(f"identified torque balance: unknown columns {unknown}")
        return cls(d["target"], list(d["names"]), np.asarray(d["coef"], float), np.asarray(d["cov"], float),
                   {k: float(v) for k, v in d["shape"].items()}, {k: float(v) for k, v in d["shape_sd"].items()},
                   {k: bool(v) for k, v in d.get("identified", {}).items()}, list(d.get("notes", [])),
                   float(d.get("cv_rmse", np.nan)), float(d.get("rmse", np.nan)),
                   float(d.get("cutoff_hz", DERIV_CUTOFF_HZ)))


def identify_torque_balance(signals, target: str = "Q_red", *, blocks_per_file: int = 4,
                            cutoff_hz: float = DERIV_CUTOFF_HZ, standstill_sigmas: float = 3.0,
                            weights: np.ndarray | None = None, const: str = "auto",
                            wald_sigmas: float = 3.0) -> Identified:
    """Identify the motor-side torque balance with an identified Coulomb transition width.

    ``target="Q_red"``: Q_red ~ a tau_m + b alpha_m + c tanh(omega_m / width) + d omega_m (+ e);
    ``target="tau_m"``:  tau_m ~ a Q_red + b alpha_m + c tanh(omega_m / width) + d omega_m (+ e)
    (a = 1/(N eta), b = J_eq, c = T_C, d = b_visc; without Q_red the load column is left out, noted).
    ``signals``: a dict of arrays (``t``, ``omega_m``, ``tau_m``, ``Q_red``; optional ``file``, ``segment``,
    ``alpha_m``) or a list of such dicts (one per file); see :func:`prepare_signals`.

    Rows at standstill (|omega_m| < ``standstill_sigmas`` x the speed-noise sigma) are left out: the
    friction there is static and the measured sign is noise. The width is searched between a tenth of
    that noise sigma and half the q90 speed; if the data have no zero crossings (motion in one direction)
    it is not identifiable and the note says so. The constant enters (``const="auto"``) only if it
    lowers the CV error and its jackknife z reaches ``wald_sigmas``; ``"yes"``/``"no"`` force it.
    """
    if target not in ("Q_red", "tau_m"):
        raise IdentifyError(f"target must be 'Q_red' or 'tau_m', not {target!r}")
    s = prepare_signals(signals, blocks_per_file=blocks_per_file, cutoff_hz=cutoff_hz)
    other = "tau_m" if target == "Q_red" else "Q_red"
    for k in ("omega_m", target):
        if k not in s:
            raise IdentifyError(f"identify_torque_balance: signal {k} missing (have {sorted(s)})")
    notes: list[str] = []
    names = [other, "alpha_m", "coulomb", "omega_m"]
    if other not in s or np.std(s[other]) == 0:
        if target == "Q_red":
            raise IdentifyError("identify_torque_balance(target='Q_red') needs tau_m")
        names.remove(other)
        notes.append("Q_red not measured: the load path Q_red/(N eta) is absent from the tau_m balance")
    w = s["omega_m"]
    sig_w = max((speed_noise_sigma(w[s["file"] == f], s.get("segment", s["file"])[s["file"] == f])
                 for f in np.unique(s["file"])), default=0.0)
    keep = np.ones(len(w), bool)
    if standstill_sigmas > 0 and sig_w > 0:
        keep = np.abs(w) >= standstill_sigmas * sig_w
        if keep.mean() < 0.1:
            keep[:] = True
            notes.append("almost no motion above the speed noise: standstill rows kept")
        elif (~keep).any():
            notes.append(f"{int((~keep).sum())} standstill samples (|omega_m| < {standstill_sigmas:g} x speed-noise "
                         f"sigma {sig_w:.3g} rad/s) left out: static friction is unobservable there")
    s = {k: v[keep] for k, v in s.items()}
    wts = None if weights is None else np.asarray(weights, float)[keep]
    w = s["omega_m"]
    scale = float(np.quantile(np.abs(w), 0.9))
    if scale <= 0:
        raise IdentifyError("omega_m is zero throughout: no torque balance can be identified")
    moving = np.abs(w) > 0.02 * scale
    reversal = min(np.mean(w[moving] > 0), np.mean(w[moving] < 0)) if moving.any() else 0.0
    lo = max(sig_w / 10, 1e-4 * scale, 1e-6)
    shapes = [Shape("width", lo, max(0.5 * scale, 10 * lo), log=True, n_grid=12)]
    if reversal < 0.02:
        notes.append("omega_m: motion in one direction only (no zero crossings): the Coulomb transition width is "
                     "not identifiable and the Coulomb term is collinear with a constant; width kept at the lower "
                     "bound (a hard sign), constant left out")
        const = "no"

    def fit(cols):
        def design(sh):
            return np.stack([COLUMNS[n](s, sh) for n in cols], 1)
        return fit_separable(s[target], design, cols, s["block"], shapes if "coulomb" in cols else [],
                             weights=wts)

    res = fit(names)
    if const in ("auto", "yes"):
        rc = fit(names + ["const"])
        z = abs(rc.coef[-1]) / max(np.sqrt(rc.cov[-1, -1]), 1e-300)
        if const == "yes" or (rc.cv_rmse < res.cv_rmse and z >= wald_sigmas):
            res = rc
            names = names + ["const"]
        else:
            notes.append(f"constant offset not identified (jackknife z {z:.1f}, CV RMSE {rc.cv_rmse:.4g} vs "
                         f"{res.cv_rmse:.4g} without): left out")
    shape, shape_sd, ident = res.shape, res.shape_sd, res.identified
    if reversal < 0.02:
        shape, shape_sd, ident = {"width": lo}, {"width": float("nan")}, {"width": False}
        res.notes = [n for n in res.notes if not n.startswith("width")]
    elif shape.get("width", lo) < 2 * sig_w:
        # a measured speed with noise sigma turns even a hard sign into a transition about sigma wide
        ident = dict(ident, width=False)
        notes.append(f"width {shape['width']:.3g} rad/s is within 2x the speed-noise sigma {sig_w:.3g} rad/s: the "
                     "transition is not resolved beyond the measurement noise (consistent with a hard sign); "
                     "the value is an upper bound")
    return Identified(target, list(names), res.coef, res.cov, shape, shape_sd, ident, notes + res.notes,
                      res.cv_rmse, res.rmse, cutoff_hz)
