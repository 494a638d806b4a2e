"""The prognostic core on real degradation data it was not built for.

* NASA PCoE Li-ion cells B0005-B0007 (capacity per discharge cycle): the
  :class:`ExponentialFade` model, end of life at 70 % or 80 % of the rated
  2.0 Ah. Leave-one-cell-out: the prior (fade rate, noise levels) is fitted on
  the *other* cells, never on the cell being predicted.
* Virkler et al. fatigue cracks (68 aluminium specimens): the
  :class:`ParisCrack` model, failure at 49.8 mm (the last length recorded).
  Specimens are split in two halves; the Paris exponent ``m`` and the prior
  on ``log C'`` are fitted on the training half and the filter is scored on
  the other half, then the halves swap (2-fold).

Units. ``VirklerData.csv``'s ``V2`` is in **kilocycles** (1000 cycles).
``VirklerData-Raw.csv`` holds digitisation coordinates, not cycle counts:
column ``9`` (mm) is the plot's origin (0 cycles, the same value for every
specimen within a few units) and column ``3200 Limit`` the coordinate of
3200 hundred cycles (320 000 cycles), so ``N = (x - x_9) / (x_limit - x_9) *
320000``. This mapping reproduces ``V2`` within 1 kcycle at every length
(checked in :func:`load_virkler`, which raises if it does not).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hd_prognostic import metrics as M
from hd_prognostic.models import ExponentialFade, ParisCrack
from hd_prognostic.tracking import RULHistory, track

RATED_AH = 2.0
VIRKLER_LENGTHS_MM = np.array([9, 11, 13, 17, 20, 26, 33, 39, 49.8])


# ---------------------------------------------------------------- battery ---
def load_battery(cell: str, data_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(cycle, capacity Ah) of a NASA cell (``data_dir/B0005.csv`` ...); raises on a missing/corrupt file."""
    p = Path(data_dir) / f"{cell}.csv"
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such battery file")
    try:
        a = np.genfromtxt(p, delimiter=",", names=True)
        cyc, cap = np.asarray(a["cycle"], float), np.asarray(a["capacity_ah"], float)
    except (ValueError, KeyError) as e:
        raise ValueError(f"{p}: expected columns cycle,capacity_ah ({e})") from e
    ok = np.isfinite(cyc) & np.isfinite(cap)
    if ok.sum() < 10:
        raise ValueError(f"{p}: fewer than 10 valid rows")
    o = np.argsort(cyc[ok])
    return cyc[ok][o], cap[ok][o]


def battery_eol(cycle, cap, c_eol: float) -> float:
    """First cycle with measured capacity <= c_eol (NaN if never reached)."""
    i = np.flatnonzero(np.asarray(cap) <= c_eol)
    return float(cycle[i[0]]) if len(i) else float("nan")


def fit_fade_prior(curves: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """Prior of :class:`ExponentialFade` from training curves (not the cell under test).

    Per curve: log-linear least squares ``ln C = ln C0 + b k`` on the whole
    curve gives ``b``; the residual of a local (11-cycle) fit gives the
    measurement noise; the spread of the global fit residual increments the
    process noise.
    """
    bs, c0s, s_obs, s_proc = [], [], [], []
    for k, c in curves:
        A = np.column_stack([np.ones_like(k), k])
        coef, *_ = np.linalg.lstsq(A, np.log(c), rcond=None)
        c0s.append(np.exp(coef[0]))
        bs.append(coef[1])
        # local noise: residual of a moving 11-point linear fit
        r = c - np.convolve(np.pad(c, 5, mode="edge"), np.ones(11) / 11, mode="valid")
        s_obs.append(1.4826 * np.median(np.abs(r - np.median(r))))
        s_proc.append(np.std(np.diff(c - np.exp(A @ coef))) / np.sqrt(2))
    bs = np.array(bs)
    return {
        "b_mean": float(np.mean(bs)),
        "b_std": float(max(np.std(bs), 0.5 * abs(np.mean(bs)))),
        "C0_mean": float(np.mean(c0s)),
        "C0_std": float(max(np.std(c0s), 0.05)),
        "sigma_obs": float(np.mean(s_obs)),
        "sigma_C": float(np.mean(s_proc)) * 0.5,
        "sigma_b": float(max(np.std(bs), 0.5 * abs(np.mean(bs)))) / 20.0,
    }


def run_battery(data_dir: str | Path, cells=("B0005", "B0006", "B0007"), eol_fracs=(0.7, 0.8), n_particles: int = 2000,
                t_start: float = 20.0, seed: int = 0,
                likelihood: str = "student_t", progress: bool = False, regen_nu: float = 0.0) -> dict:
    """Leave-one-cell-out PF prognosis of every cell for each EOL definition.

    Returns ``{"units": {f"{cell}@{frac}": {"history": RULHistory, "metrics": ..., "prior": ...}}, "aggregate": ...}``.
    Cells that never reach the EOL capacity inside the data are reported as skipped.
    ``regen_nu > 0``: asymmetric regeneration-aware likelihood (see
    :class:`ExponentialFade`; 1.0 = Cauchy upper tail); 0 (default): the symmetric ``likelihood``.
    """
    data = {c: load_battery(c, data_dir) for c in cells}
    out: dict = {"units": {}, "skipped": {}, "aggregate": {}}
    for frac in eol_fracs:
        c_eol = frac * RATED_AH
        per = []
        for cell in cells:
            cyc, cap = data[cell]
            t_eol = battery_eol(cyc, cap, c_eol)
            if not np.isfinite(t_eol):
                out["skipped"][f"{cell}@{frac}"] = f"capacity never reaches {c_eol:.2f} Ah in the data"
                continue
            prior = fit_fade_prior([data[c] for c in cells if c != cell])
            model = ExponentialFade(C_eol=c_eol, regen_nu=regen_nu, **prior)
            dt = np.diff(np.concatenate([[cyc[0] - 1], cyc]))
            hist = track(model, cyc, cap, dt, 1.0, rul_step=1.0, max_steps=600, t_start=t_start,
                         unit=f"{cell}@{int(frac * 100)}%",
                         pf_kwargs=dict(n_particles=n_particles, seed=seed, likelihood=likelihood,
                                        roughening=0.05), progress=progress)
            sel = np.asarray(hist.rul_t) < t_eol
            m = M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, t_eol,
                                samples=hist.samples, t_p=t_start, rul_horizon=hist.meta.get("rul_horizon"))
            hist.meta.update({"t_eol": t_eol, "c_eol": c_eol, "prior": prior, "regen_nu": regen_nu})
            out["units"][f"{cell}@{frac}"] = {"history": hist, "metrics": m, "n_before_eol": int(sel.sum())}
            per.append(m)
        out["aggregate"][str(frac)] = M.aggregate(per)
    return out


# ---------------------------------------------------------------- Virkler ---
@dataclass
class Specimen:
    sid: int
    N: np.ndarray  # cycles
    a: np.ndarray  # m
    N_fail: float  # cycles at a = 49.8 mm


def load_virkler(data_dir: str | Path, check_units: bool = True) -> list[Specimen]:
    """All 68 specimens of ``data_dir`` (VirklerData-Raw.csv + VirklerData.csv): processed grid points
    (V2 kcycles) merged with the raw lengths (mapped to cycles)."""
    d = Path(data_dir)
    praw, pproc = d / "VirklerData-Raw.csv", d / "VirklerData.csv"
    for p in (praw, pproc):
        if not p.exists():
            raise FileNotFoundError(f"{p}: missing Virkler file")
    with open(praw, newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    try:
        lengths = np.array([float(h) for h in head[1:10]])
    except ValueError as e:
        raise ValueError(f"{praw}: unexpected header {head!r}") from e
    if not np.allclose(lengths, VIRKLER_LENGTHS_MM) or "limit" not in head[10].lower():
        raise ValueError(f"{praw}: header {head!r} is not the expected lengths + '3200 Limit' column")
    raw = np.array([[float(v) for v in r[:11]] for r in rows[1:] if r and r[0].strip()])
    proc = np.genfromtxt(pproc, delimiter=",", skip_header=1)
    if proc.ndim != 2 or proc.shape[1] != 3:
        raise ValueError(f"{pproc}: expected 3 columns V1,V2,V3")
    out = []
    for r in raw:
        sid = int(r[0])
        x, x0, xl = r[1:10], r[1], r[10]
        N_raw = (x - x0) / (xl - x0) * 320000.0
        p = proc[proc[:, 0] == sid]
        N_p, a_p = p[:, 1] * 1000.0, p[:, 2]
        if check_units and len(p) > 2:
            inside = (lengths > a_p.min()) & (lengths < a_p.max())
            dev = np.abs(np.interp(lengths[inside], a_p, N_p) - N_raw[inside])
            if dev.size and dev.max() > 3000:
                raise ValueError(f"{praw}: specimen {sid}: raw-to-cycles mapping disagrees with {pproc.name} "
                                 f"by {dev.max():.0f} cycles")
        N = np.concatenate([N_raw, N_p])
        a = np.concatenate([lengths, a_p]) * 1e-3
        o = np.argsort(N, kind="stable")
        N, a = N[o], a[o]
        keep = np.concatenate([[True], np.diff(N) > 500])  # one point per ~0.5 kcycle
        out.append(Specimen(sid, N[keep], a[keep], float(N_raw[-1])))
    return out


def _paris_grow(a0, logC, N, m):
    """Closed-form Paris integration (same law as :meth:`ParisCrack.grow`), vectorised."""
    q = 1.0 - 0.5 * m
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        base = np.power(a0, q) + q * np.exp(logC) * N
        return np.where(base > 0, np.power(np.maximum(base, 1e-300), 1.0 / q), np.inf)


def fit_paris(train: list[Specimen]) -> dict:
    """Paris exponent m (shared) and the distribution of ln C' from training specimens.

    For a given m the integrated law is linear in C' after the transform
    ``Y = (a^(1-p) - a0^(1-p)) / (1-p) = C' N`` (p = m/2), so each specimen's
    C' is a one-line least-squares fit; m minimises the pooled squared
    log-error of the integrated curves (bounded scalar search). Also returns
    the observation noise (robust residual std, m) and the initial-length
    spread.
    """
    from scipy.optimize import minimize_scalar as _ms

    def fit_all(m: float):
        q = 1.0 - 0.5 * m
        lcs, err = [], 0.0
        for s in train:  # over specimens (tens), each vectorised over its points
            N = s.N - s.N[0]
            Y = (np.power(s.a, q) - np.power(s.a[0], q)) / q
            C = max(float(np.sum(N * Y) / max(np.sum(N * N), 1e-300)), 1e-300)
            lc = float(np.log(C))
            pred = _paris_grow(s.a[0], lc, N, m)
            e = np.log(np.where(np.isfinite(pred) & (pred > 0), pred, 1.0)) - np.log(s.a)
            lcs.append(lc)
            err += float(np.sum(e * e))
        return np.array(lcs), err

    r = _ms(lambda m: fit_all(m)[1], bounds=(2.2, 5.0), method="bounded", options={"xatol": 1e-3})
    m = float(r.x)
    lcs, _ = fit_all(m)
    res = np.concatenate([s.a - _paris_grow(s.a[0], lc, s.N - s.N[0], m) for s, lc in zip(train, lcs)])
    res = res[np.isfinite(res)]
    return {
        "m": m,
        "logC_mean": float(np.mean(lcs)),
        "logC_std": float(np.std(lcs)),
        "sigma_obs": float(max(1.4826 * np.median(np.abs(res)), 0.05e-3)),
        "a0_mean": float(np.mean([s.a[0] for s in train])),
        "a0_std": float(max(np.std([s.a[0] for s in train]), 0.05e-3)),
    }


def run_virkler(data_dir: str | Path, n_particles: int = 2000, seed: int = 0, rul_step: float = 1000.0,
                max_specimens: int | None = None, progress: bool = False) -> dict:
    """2-fold (odd/even specimen) Paris-law PF prognosis; metrics per held-out specimen."""
    specs = load_virkler(data_dir)
    folds = [[s for s in specs if s.sid % 2 == 1], [s for s in specs if s.sid % 2 == 0]]
    out: dict = {"units": {}, "fits": []}
    per = []
    for fi in range(2):
        train, test = folds[fi], folds[1 - fi]
        fit = fit_paris(train)
        out["fits"].append(fit)
        if max_specimens:
            test = test[:max_specimens]
        for s in test:
            model = ParisCrack(a_crit=49.8e-3, m=fit["m"], logC_mean=fit["logC_mean"], logC_std=fit["logC_std"],
                               a0_mean=fit["a0_mean"], a0_std=fit["a0_std"], sigma_obs=fit["sigma_obs"],
                               sigma_proc=0.05, sigma_logC=0.01)
            sel = s.N < s.N_fail  # observations before failure only
            N, a = s.N[sel], s.a[sel]
            dN = np.diff(np.concatenate([[N[0]], N]))
            hist = track(model, N, a, dN, rul_step, rul_step=rul_step, max_steps=800, t_start=N[1] if len(N) > 1 else 0,
                         unit=f"specimen{s.sid}", pf_kwargs=dict(n_particles=n_particles, seed=seed + s.sid,
                                                                   roughening=0.05), progress=progress)
            m = M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, s.N_fail, samples=hist.samples,
                                rul_horizon=hist.meta.get("rul_horizon"))
            hist.meta.update({"t_eol": s.N_fail, "fit": fit})
            out["units"][s.sid] = {"history": hist, "metrics": m}
            per.append(m)
    out["aggregate"] = M.aggregate(per)
    return out


# ------------------------------------------------- the same data as HI CSV + events for the life model ---
def battery_records(data_dir: str | Path, out_dir: str | Path, cells=("B0005", "B0006", "B0007"),
                    eol_frac: float = 0.8) -> tuple[Path, Path]:
    """Write ``battery_hi.csv`` (unit,time,hi = cycle, capacity Ah) and ``battery_events.csv`` (failure =
    first cycle with capacity <= eol_frac x rated, found at that cycle; cells that never reach it have no
    row: censored at their last cycle) for ``hdphm prognostic fit`` / ``prognose``."""
    from hd_prognostic.lifemodel import UnitEvents, UnitHistory, write_events, write_hi_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    units, ev = [], {}
    for c in cells:
        cyc, cap = load_battery(c, data_dir)
        units.append(UnitHistory(c, cyc, cap, cyc.copy()))
        t = battery_eol(cyc, cap, eol_frac * RATED_AH)
        if np.isfinite(t):
            ev[c] = UnitEvents(failure=float(t))
    write_hi_csv(out / "battery_hi.csv", units)
    write_events(out / "battery_events.csv", ev)
    return out / "battery_hi.csv", out / "battery_events.csv"


def virkler_records(data_dir: str | Path, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``virkler_hi.csv`` (unit,time,hi = specimen, cycles, crack length m; records through the failure:
    the measured 49.8 mm at the failure count is the last row, as the measured capacity at the failure cycle is
    in ``battery_records``'s file; a fit drops records at or after the failure and
    :func:`hd_prognostic.lifemodel.failure_at_rule` reads it as a recorded crossing) and ``virkler_events.csv``
    (failure at the cycle count of the last recorded length, 49.8 mm)."""
    from hd_prognostic.lifemodel import UnitEvents, UnitHistory, write_events, write_hi_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    units, ev = [], {}
    for s in load_virkler(data_dir):
        sel = s.N <= s.N_fail
        units.append(UnitHistory(f"specimen{s.sid}", s.N[sel], s.a[sel], s.N[sel].copy()))
        ev[f"specimen{s.sid}"] = UnitEvents(failure=float(s.N_fail))
    write_hi_csv(out / "virkler_hi.csv", units)
    write_events(out / "virkler_events.csv", ev)
    return out / "virkler_hi.csv", out / "virkler_events.csv"
