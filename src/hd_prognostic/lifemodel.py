"""A fleet life model fitted from what an operator records: health-indicator histories and events.

Inputs per unit (no simulator truth anywhere):

* a health-indicator (HI) history ``(t_j, y_j)`` (onboard feature per mission, or any CSV series) and the
  cumulative exposure ``E(t)`` (missions, operating hours, or the load-based Archard exposure summed from
  the bags);
* events (:func:`read_events`): ``failure`` at ``t_f`` (found failed at the start of ``t_f``: it ran up to
  its previous record), ``removal`` at ``t_c`` (healthy when removed: right-censored), ``inspection``
  (``quantity`` = ``value`` measured at ``t``). A unit without a failure or removal row is censored at its
  last record.

Model (latent degradation path, population of units):

* latent degradation ``L_i(E) = r_i (E / E_ref)^b``, per-unit rate ``ln r_i ~ N(mu, s^2)``, shared shape
  exponent ``b`` (fitted: the law's shape comes from the data);
* or (``path="paris"``, crack-growth shape) ``L_i(E) = h(r_i E / E_ref) / D0``, ``h(u) = (1 - u)^(-p) - 1`` (Paris'
  law with dK ~ sqrt(a) integrated: finite-time blow-up at ``E_ref / r_i``); ``path="auto"`` fits both and keeps the
  lower AIC (per fit, never per scored unit); see :func:`_path_L`;
* HI: ``y_ij = a_i + c L_i(E_ij) + e_ij``, per-unit offset ``a_i ~ N(a0, s_a^2)`` (marginalised
  analytically), AR(1) residuals ``e_ij = rho e_i(j-1) + N(0, sigma^2)`` (prewhitened; rho fitted); or
  (``noise="level"``, ``"auto"``: by AIC) a residual sd growing with the degradation, ``sigma sqrt(1 + kappa^2 L^2)``,
  the standardised residuals ``e / s`` being the AR(1) chain (:meth:`_Batch._hstats`);
* failure when ``L_i`` crosses the unit's threshold ``D_i``, ``ln D_i ~ N(0, s_D^2)`` (median threshold 1
  fixes the latent scale; ``c`` is the HI change at the median threshold);
* inspection of quantity q: ``v = alpha_q + beta_q L_i + N(0, tau_q^2)`` (population-level map, fitted
  when the quantity has >= 4 inspections in the fleet; otherwise ignored with a note).
* or (``threshold="observable"``) failure when the *measured* HI crosses the unit's level ``Y_i ~ N(Y0, s_Y^2)``
  in the direction of ``c`` (failure defined on a measurement: capacity fraction, crack length, a lost-motion
  limit); the latent scale is then fixed by ``mu = 0``. ``threshold="auto"`` fits both and keeps the higher
  maximum likelihood (same number of parameters: also the AIC choice); never chosen per scored unit.

Likelihood of unit i (exact up to a 1-D quadrature over ``z = ln r_i``, on an adaptive grid):
``p_i = int N(z; mu, s) p(y_i | z) prod_insp p(v | z) P(event | z) dz`` with
``P(failure in (E_lo, E_hi] | z) = Phi((z + b ln E_hi)/s_D) - Phi((z + b ln E_lo)/s_D)`` (interval censored:
it failed between its last record and the mission it was found failed at) and
``P(survive to E_c | z) = Phi(-(z + b ln E_c)/s_D)``. All parameters by maximum likelihood (L-BFGS-B, then a
short Nelder-Mead polish, on the summed log marginal likelihood, started from per-unit least squares).

Observable threshold (given z, the offset's conditional law given the record is normal, so the event terms stay
closed-form): ``P(failure) = P(M < Y <= y_f) ~ Phi((m_f - Y0)/sqrt(s_Y^2 + v_f)) - Phi((M - Y0)/s_Y)`` (oriented by
the sign of c), ``y_f ~ N(m_f, v_f)`` the unrecorded HI at the failure time (offset posterior, AR(1) residual carried
on from the last record), M the record's extreme; censored: ``P(Y > M)``. Its prognosis simulates the unit's future
HI records from its posterior until they pass a threshold drawn from its law truncated to ``Y > M``.
``failure_at="crossing"`` (failure time = the time the measured HI reached the level, continuous records): the event
term is that crossing time's density, ``N(Y0; m_f, s_Y^2 + v_f) |c dL/d ln E|`` at the failure exposure; with a known
``failure_level`` the defined level and a fitted one are compared by AIC (a path whose shape is wrong between the last
records and the level does not reach the defined level at the failure times: Virkler, records up to 39 mm, failure at
49.8 mm).

Parameter draws: uniform prior on the standard deviations with >= 3 failures (Gelman 2006's default); with 2, where
that posterior is improper, half-Cauchy priors on the between-unit scales (``s``: scale 1, ``s_a`` and ``s_Y``: the
HI's standard deviation over the training records, ``s_D``: 1), Gelman's recommendation for few groups.

Prognosis of one unit at time t_k (latent threshold): the posterior over z on the same grid (its HI and inspections
up to t_k, survival to ``E(t_k)``), then ``ln D`` from its prior truncated to ``ln D > z + b ln E(t_k)``, the failure
exposure ``E_f = E_ref (D / r)^(1/b)`` and the failure time from the unit's own exposure rate.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import optimize, sparse, special

from hd_prognostic.ukf import merwe_weights

EVENT_KINDS = ("failure", "removal", "inspection")
EVENT_COLUMNS = ("actuator_id", "mission_index", "event", "quantity", "value")
EXPOSURES = ("missions", "hours", "load")
THRESHOLDS = ("latent", "observable")  # where the failure threshold sits (LifeModel.fit(threshold=...))
#: the future exposure's variability in the prognosis (LifeModel.fit(exposure_spread=...)): none, the renewal
#: spread of the unit's i.i.d. increments, or that plus the sampling uncertainty of its mean rate
SPREADS = ("none", "renewal", "renewal+rate")
SCALE_PRIORS = ("uniform", "log")  # prior of the between-unit scales in the parameter draws (LifeModel.fit)
NOISES = ("constant", "level")  # HI noise model (LifeModel.fit(noise=...)): one sigma, or growing with the level
GAINS = ("shared", "unit")  # HI gain (LifeModel.fit(hi_gain=...)): one c, or c (1 + g_i) per unit (theta log_sg)
MIN_INSPECTIONS = 4  # per quantity, fleet-wide, to fit its (alpha, beta, tau) map
_LOG2PI = math.log(2 * math.pi)


# ---------------------------------------------------------------------------------------------- events ---
@dataclass
class UnitEvents:
    failure: float | None = None
    removal: float | None = None
    inspections: list[tuple[float, str, float]] = field(default_factory=list)  # (t, quantity, value SI)


def _open_text(p: Path) -> io.StringIO:
    """The whole file as text for :mod:`csv`; a file that is not UTF-8 text is named in the error."""
    try:
        return io.StringIO(p.read_text(encoding="utf-8-sig"), newline="")
    except UnicodeDecodeError as e:
        raise ValueError(f"{p}: not UTF-8 text (byte {e.start}: {e.reason}); expected a CSV file") from None


def _csv_rows(f: io.StringIO):
    """A :mod:`csv` reader over ``f`` in the file's own delimiter: comma, or semicolon / tab where the header line
    has one of those and no comma (spreadsheet exports in locales with a decimal comma, TSV)."""
    head = f.readline()
    f.seek(0)
    delim = ","
    if "," not in head:
        delim = next((d for d in (";", "\t") if d in head), ",")
    return csv.reader(f, delimiter=delim)


def _number(text: str, rd) -> float:
    """``float(text)``; in a semicolon-separated file a decimal comma ("0,5") is read as the decimal point it is."""
    if rd.dialect.delimiter == ";" and "," in text and "." not in text:
        text = text.replace(",", ".")
    return float(text)


def _header(row: list[str]) -> list[str]:
    """Column names as the readers match them: stripped, lower case."""
    return [h.strip().lower() for h in row]


def read_events(path: str | Path) -> dict[str, UnitEvents]:
    """Parse an events CSV (columns :data:`EVENT_COLUMNS`); every error names the file and row."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: events file not found")
    out: dict[str, UnitEvents] = {}
    with _open_text(p) as f:
        rd = _csv_rows(f)
        try:
            head = _header(next(rd))
        except StopIteration:
            raise ValueError(f"{p}: empty events file (expected header {','.join(EVENT_COLUMNS)})") from None
        miss = [c for c in EVENT_COLUMNS[:3] if c not in head]
        if miss:
            raise ValueError(f"{p}: row 1 (header): missing column(s) {miss}; expected {','.join(EVENT_COLUMNS)}")
        ix = {c: head.index(c) for c in EVENT_COLUMNS if c in head}
        for n, row in enumerate(rd, start=2):
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            where = f"{p}: row {n}"
            if len(row) < len(head):
                row = row + [""] * (len(head) - len(row))
            unit = row[ix["actuator_id"]].strip()
            kind = row[ix["event"]].strip().lower()
            if not unit:
                raise ValueError(f"{where}: empty actuator_id")
            if kind not in EVENT_KINDS:
                raise ValueError(f"{where}: event {row[ix['event']]!r} is not one of {', '.join(EVENT_KINDS)}")
            try:
                t = _number(row[ix["mission_index"]], rd)
            except ValueError:
                raise ValueError(f"{where}: mission_index {row[ix['mission_index']]!r} is not a number") from None
            if not math.isfinite(t) or t < 0:
                raise ValueError(f"{where}: mission_index {t} must be finite and >= 0")
            ev = out.setdefault(unit, UnitEvents())
            if kind == "inspection":
                q = row[ix["quantity"]].strip() if "quantity" in ix else ""
                if not q:
                    raise ValueError(f"{where}: inspection without a quantity")
                try:
                    v = _number(row[ix["value"]], rd) if "value" in ix else float("nan")
                except ValueError:
                    raise ValueError(f"{where}: inspection value {row[ix['value']]!r} is not a number") from None
                if not math.isfinite(v):
                    raise ValueError(f"{where}: inspection value must be a finite number (SI units)")
                ev.inspections.append((t, q, v))
            else:
                if ev.failure is not None or ev.removal is not None:
                    raise ValueError(f"{where}: {unit} already has a failure/removal row (one end of life per unit)")
                if kind == "failure":
                    ev.failure = t
                else:
                    ev.removal = t
    return out


def write_events(path: str | Path, events: dict[str, UnitEvents]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(EVENT_COLUMNS)
        for u in sorted(events):
            e = events[u]
            for t, q, v in e.inspections:
                w.writerow([u, _num(t), "inspection", q, repr(float(v))])
            if e.failure is not None:
                w.writerow([u, _num(e.failure), "failure", "", ""])
            if e.removal is not None:
                w.writerow([u, _num(e.removal), "removal", "", ""])


def _num(t: float) -> str:
    return str(int(t)) if float(t).is_integer() else repr(float(t))


# ------------------------------------------------------------------------------------------ unit data ---
@dataclass
class UnitHistory:
    """One unit's HI history and exposure. ``E`` is the cumulative exposure at the record times ``t``;
    ``t_next``/``E_next`` the exposure at the step after the last record when known (bags: + that mission's
    own exposure); ``discrete`` when time counts whole steps (missions, cycles)."""

    unit: str
    t: np.ndarray
    y: np.ndarray
    E: np.ndarray
    discrete: bool = True
    E_next: float | None = None
    hours_per_step: float | None = None
    events: UnitEvents = field(default_factory=UnitEvents)
    notes: list[str] = field(default_factory=list)
    #: (t, y) of the first finite record at or after the failure (kept by :func:`attach_events` when it drops
    #: those records): what :func:`failure_at_rule` reads to tell a failure defined as the recorded HI reaching
    #: a level from one found at an inspection
    failure_record: tuple[float, float] | None = None

    def rate(self, estimator: str = "median") -> float:
        """Exposure per time unit over the record (for extrapolation). ``median`` (the default): the median of
        the per-step rates; ``mean``: the exposure accrued over the steps with a known increment divided by their
        time, the long-run accumulation rate (renewal theory: N(E) ~ E / mean). They differ where the per-step
        increments are right-skewed (per-mission load work: the mean is 4.7 % above the median on average over the
        dev fleet's units, -1.4 to +11.7 %, so the median extrapolates a failure exposure to a later time). The
        prognosis uses :meth:`LifeModel.fit`'s ``exposure_rate`` (``src/hd_prognostic/README.md``, "Dev-fleet
        coverage diagnosis")."""
        if estimator not in ("median", "mean"):
            raise ValueError(f"exposure rate estimator {estimator!r} is not one of median, mean")
        dt, dE, ok = self._increments()
        if ok.any():
            if estimator == "mean":
                return float(np.sum(dE[ok]) / np.sum(dt[ok]))
            return float(np.median(dE[ok] / dt[ok]))
        if self.E_next is not None and len(self.t):
            return float(self.E_next - self.E[-1])
        return float("nan")

    def rate_var(self) -> float:
        """Variance per time unit of the exposure increments about the mean rate (:meth:`rate` ``mean``): the
        increments taken as independent with variance proportional to their time (for unit steps: the sample
        variance of the per-step exposures), ``sum (dE - m dt)^2 / sum dt * n / (n - 1)``; 0 with fewer than two
        known increments or a relative spread below 1e-6 (an exposure that is the time column)."""
        dt, dE, ok = self._increments()
        n = int(ok.sum())
        if n < 2:
            return 0.0
        m = float(np.sum(dE[ok]) / np.sum(dt[ok]))
        v = float(np.sum((dE[ok] - m * dt[ok]) ** 2) / np.sum(dt[ok]) * n / (n - 1))
        return v if m > 0 and v > (1e-6 * m) ** 2 else 0.0

    def rate_mean_var(self) -> float:
        """Sampling variance of the mean rate (:meth:`rate` ``mean``) under the same model as :meth:`rate_var`:
        ``v / sum dt`` over the known increments (for unit steps: the per-step variance over their number n, i.e.
        sd = cv m / sqrt(n)); 0 where :meth:`rate_var` is 0."""
        v = self.rate_var()
        if v <= 0:
            return 0.0
        dt, _, ok = self._increments()
        return v / float(np.sum(dt[ok]))

    def _increments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-step time and exposure increments of the record and the steps with a known one (dt > 0, dE >= 0)."""
        dt, dE = np.diff(self.t), np.diff(self.E)
        return dt, dE, (dt > 0) & np.isfinite(dE) & (dE >= 0)

    def exposure_at(self, t: float, rate: float | None = None) -> float:
        """Cumulative exposure at time ``t`` (interpolated; beyond the record: next-step value, then rate)."""
        if t <= self.t[-1]:
            return float(np.interp(t, self.t, self.E))
        r = self.rate() if rate is None else rate
        if self.E_next is not None and self.discrete:
            return float(self.E_next + (t - self.t[-1] - 1) * r)
        return float(self.E[-1] + (t - self.t[-1]) * r)

    def truncated(self, t_k: float) -> "UnitHistory":
        """The record up to and including ``t_k`` (what is known at that time)."""
        m = self.t <= t_k
        if m.all():
            E_next = self.E_next
        else:  # the exposure up to the next step is known once the step at t_k is flown
            E_next = float(self.exposure_at(self.t[m][-1] + 1)) if self.discrete else None
        ev = UnitEvents(inspections=[x for x in self.events.inspections if x[0] <= t_k])
        return UnitHistory(self.unit, self.t[m], self.y[m], self.E[m], self.discrete, E_next,
                           self.hours_per_step, ev)


def attach_events(units: list[UnitHistory], events: dict[str, UnitEvents], source: str = "events") -> list[str]:
    """Give each unit its events; drop HI records at or after a failure; return notes (unknown ids...)."""
    notes = []
    ids = {u.unit for u in units}
    extra = sorted(set(events) - ids)
    # ids that differ only in case (a spreadsheet that upper-cased them): the same unit when the match is unique
    by_fold: dict[str, list[str]] = {}
    for i in ids:
        by_fold.setdefault(i.casefold(), []).append(i)
    events = dict(events)
    for e in list(extra):
        hit = by_fold.get(e.casefold(), [])
        if len(hit) == 1 and hit[0] not in events:
            events[hit[0]] = events.pop(e)
            extra.remove(e)
            notes.append(f"{source}: unit {e!r} taken as {hit[0]!r} (the ids differ only in case)")
    if extra:
        notes.append(f"{source}: {len(extra)} unit(s) with events but no health-indicator history ignored: "
                     f"{', '.join(extra[:5])}")
    for u in units:
        ev = events.get(u.unit, UnitEvents())
        u.events = ev
        u.failure_record = None
        if ev.failure is not None:
            if not (u.t < ev.failure).any():
                raise ValueError(f"{source}: {u.unit}: failure at {ev.failure:g} is not after its first record "
                                 f"({u.t[0]:g})")
            gap = ev.failure - u.t[-1]
            if gap > max(1.0, u.t[-1] - u.t[0]):  # more unrecorded life than recorded: say so, keep the event
                notes.append(f"{source}: {u.unit}: failure at {ev.failure:g} is {gap:g} after its last "
                             f"health-indicator record ({u.t[-1]:g}); the exposure in between is extrapolated "
                             f"at the unit's median rate")
            late = u.t >= ev.failure
            fin = np.flatnonzero(late & np.isfinite(u.y))
            u.failure_record = (float(u.t[fin[0]]), float(u.y[fin[0]])) if len(fin) else None
            if late.any():
                notes.append(f"{u.unit}: {int(late.sum())} record(s) at or after the failure at {ev.failure:g} not used")
                keep = u.t[~late]
                if u.discrete:
                    u.E_next = float(u.exposure_at(keep[-1] + 1))
                u.t, u.y, u.E = keep, u.y[~late], u.E[~late]
    return notes


FAILURE_AT = ("interval", "crossing")  # failure-time likelihoods (LifeModel.fit(failure_at=...)); "auto": the rule


def failure_at_rule(units: list[UnitHistory], failure_level: float | None) -> tuple[str, str]:
    """Which failure-time likelihood the failure *definition* calls for (never chosen by a score).

    ``crossing`` when failure is defined as the recorded HI reaching a known level (``failure_level`` given) and
    the records say every failure is that: each failed unit has a record at its failure time that has reached the
    level (kept by :func:`attach_events` as ``failure_record``) and no record before it had (NASA: the first cycle
    whose measured capacity is <= 1.6 Ah; Virkler: the cycle count at which the measured length is 49.8 mm).
    Otherwise ``interval`` (found failed at t_f: it failed somewhere after its last record): no level given, or a
    failed unit without a record at its failure time, or one whose record there has not reached the level (the
    failure was then something else). The direction of "reaching" is per unit, from its first record's side of
    the level. Returns ``(failure_at, reason)``; units without a failure do not enter."""
    failed = [u for u in units if u.events.failure is not None]
    if failure_level is None:
        return "interval", "no failure level given: failures are events (found failed), not a recorded level"
    if not failed:
        return "interval", "no failures"
    lvl = float(failure_level)
    tol = 1e-9 * max(abs(lvl), 1e-300)
    for u in failed:
        tf, rec = float(u.events.failure), u.failure_record
        if rec is None or abs(rec[0] - tf) > 1e-9 * max(abs(tf), 1.0):
            return "interval", (f"{u.unit}: no health-indicator record at its failure time {tf:g} (records must "
                                f"run through the failure to show the level was reached then)")
        ok = np.isfinite(u.y)
        y0 = float(u.y[ok][0]) if ok.any() else rec[1]
        sg = 1.0 if y0 < lvl else -1.0  # the side the unit starts on: reaching = passing to the other
        if sg * (rec[1] - lvl) < -tol:
            return "interval", (f"{u.unit}: its record at the failure time {tf:g} ({rec[1]:g}) has not reached the "
                                f"failure level {lvl:g}")
        if ok.any() and np.any(sg * (u.y[ok] - lvl) >= -tol):
            return "interval", (f"{u.unit}: a record before its failure time {tf:g} already reached the failure "
                                f"level {lvl:g}")
    return "crossing", (f"all {len(failed)} failures are the first record at or past the failure level {lvl:g}: "
                        "failure at a recorded crossing")


def read_hi_csv(path: str | Path) -> list[UnitHistory]:
    """``unit,time,hi[,exposure]`` rows (exposure cumulative; default = time). Errors name file and row."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: health-indicator CSV not found")
    rows: dict[str, list[tuple[float, float, float]]] = {}
    with _open_text(p) as f:
        rd = _csv_rows(f)
        try:
            head = _header(next(rd))
        except StopIteration:
            raise ValueError(f"{p}: empty file (expected header unit,time,hi[,exposure])") from None
        for c in ("unit", "time", "hi"):
            if c not in head:
                raise ValueError(f"{p}: row 1 (header): missing column {c!r}; expected unit,time,hi[,exposure]")
        iu, it, ih = head.index("unit"), head.index("time"), head.index("hi")
        ie = head.index("exposure") if "exposure" in head else None
        for n, r in enumerate(rd, start=2):
            if not r or all(not c.strip() for c in r):
                continue
            try:
                t, y = _number(r[it], rd), _number(r[ih], rd) if r[ih].strip() else float("nan")
                e = _number(r[ie], rd) if ie is not None else t
            except (ValueError, IndexError):
                raise ValueError(f"{p}: row {n}: time/hi/exposure not numbers: {r!r}") from None
            if not math.isfinite(t) or not math.isfinite(e):
                raise ValueError(f"{p}: row {n}: time and exposure must be finite")
            rows.setdefault(r[iu].strip(), []).append((t, y, e))
    if not rows:
        raise ValueError(f"{p}: no data rows")
    out = []
    for u, rr in rows.items():
        a = np.array(sorted(rr))
        if np.any(np.diff(a[:, 0]) == 0):
            raise ValueError(f"{p}: unit {u}: repeated time values")
        if np.any(np.diff(a[:, 2]) < 0):
            raise ValueError(f"{p}: unit {u}: exposure decreases with time (it must be cumulative)")
        t = a[:, 0]
        disc = bool(np.all(np.mod(t, 1) == 0) and len(t) > 1 and np.median(np.diff(t)) == 1)
        out.append(UnitHistory(u, t, a[:, 1], a[:, 2], discrete=disc))
    return out


def write_hi_csv(path: str | Path, units: list[UnitHistory]) -> None:
    with open(path, "w") as f:
        f.write("unit,time,hi,exposure\n")
        for u in units:
            for t, y, e in zip(u.t, u.y, u.E):
                f.write(f"{u.unit},{_num(t)},{float(y)!r},{float(e)!r}\n")


# ------------------------------------------------------------------------------------------- the model ---
def _log_diff_ndtr(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """log(Phi(hi) - Phi(lo)) for hi > lo, stable in both tails."""
    lo, hi = np.broadcast_arrays(np.asarray(lo, float), np.asarray(hi, float))
    out = np.empty(lo.shape)
    up = lo > 0  # both in the upper tail: use the survival functions
    a, b = special.log_ndtr(-lo[up]), special.log_ndtr(-hi[up])
    out[up] = a + np.log1p(-np.exp(np.minimum(b - a, 0.0)) + 1e-300)
    a, b = special.log_ndtr(hi[~up]), special.log_ndtr(lo[~up])
    out[~up] = a + np.log1p(-np.exp(np.minimum(b - a, 0.0)) + 1e-300)
    return out


def _lse(f: np.ndarray) -> np.ndarray:
    """log-sum-exp over the last axis (rows of -inf give -inf)."""
    m = np.max(f, axis=-1)
    mm = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return mm + np.log(np.sum(np.exp(f - mm[..., None]), axis=-1))


PATHS = ("power", "paris")  # latent path families (LifeModel.fit(path=...)); see _path_L
_PARIS_UMAX = 1.0 - 1e-6  # the Paris path blows up at u = 1: held finite (huge) past this


def _paris_h(u: np.ndarray, p: float) -> np.ndarray:
    """Crack-growth (Paris-type) shape ``(1 - u)^(-p) - 1``: ~ p u early, finite-time blow-up at u = 1."""
    return np.expm1(-p * np.log1p(-np.minimum(u, _PARIS_UMAX)))


def _path_L(path: str, z, lx, th: dict):
    """Latent degradation at log rate z and normalised log exposure lx (broadcast):
    power ``exp(z) (E/E_ref)^b``; paris ``h(exp(z) E/E_ref) / D0`` (z a time scale: u = r E / E_ref)."""
    b = math.exp(th["log_b"])
    if path == "power":
        return np.exp(z + b * lx)
    return _paris_h(np.exp(z + lx), b) * math.exp(-th.get("log_D0", 0.0))


def _path_logL(path: str, z, lx, th: dict):
    """ln of :func:`_path_L` (-inf at zero exposure)."""
    if path == "power":
        return z + math.exp(th["log_b"]) * lx
    with np.errstate(divide="ignore"):
        return np.log(_paris_h(np.exp(z + lx), math.exp(th["log_b"]))) - th.get("log_D0", 0.0)


class _Batch:
    """Units' data in flat arrays (normalised log exposure), so the integrand is evaluated for every unit
    at once on a (units x grid) array; only the shape exponent b changes the sufficient statistics."""

    def __init__(self, units: list[UnitHistory], E_ref: float, censor_at: list | None = None,
                 quantities: list[str] | None = None, path: str = "power", crossing: bool = False):
        self.U = len(units)
        self.path = path
        self.crossing = crossing  # failure time = the measured HI's crossing time (density), not an interval
        idx, ys, lx, link = [], [], [], []
        self.llo, self.lhi, self.lcens = (np.full(self.U, np.nan) for _ in range(3))
        qi, qu, qx, qv = [], [], [], []
        qs = {q: j for j, q in enumerate(quantities or [])}
        for i, u in enumerate(units):
            ok = np.isfinite(u.y)
            idx.append(np.full(int(ok.sum()), i))
            ys.append(u.y[ok])
            # AR(1) residual chain: a record continues the chain when the record before it is finite
            prev_ok = np.concatenate([[False], ok[:-1]])
            link.append(prev_ok[ok])
            with np.errstate(divide="ignore"):
                lx.append(np.log(np.maximum(u.E[ok], 0.0) / E_ref))
            for t, q, v in u.events.inspections:
                if q in qs:
                    qi.append(qs[q])
                    qu.append(i)
                    with np.errstate(divide="ignore"):
                        qx.append(math.log(max(u.exposure_at(t), 0.0) / E_ref) if u.exposure_at(t) > 0 else -np.inf)
                    qv.append(v)
            ev = u.events
            tc = None if censor_at is None else censor_at[i]
            if tc is None and ev.failure is not None:
                prev = u.t[u.t < ev.failure]
                lo = u.exposure_at(float(prev[-1])) / E_ref if len(prev) else 0.0
                hi = max(u.exposure_at(ev.failure) / E_ref, lo * (1 + 1e-9) + 1e-12)
                self.llo[i] = math.log(lo) if lo > 0 else -np.inf
                self.lhi[i] = math.log(hi)
            else:
                if tc is None:
                    tc = ev.removal if ev.removal is not None else u.t[-1]
                ec = u.exposure_at(tc) / E_ref
                self.lcens[i] = math.log(ec) if ec > 0 else -np.inf
        # observable threshold: last finite record (value, log exposure), running max / min of the record, and
        # the number of record steps from it to the failure (discrete: time steps; continuous: the next record)
        self.y_last, self.lx_last, self.ymax, self.ymin = (np.full(self.U, np.nan) for _ in range(4))
        self.nf = np.ones(self.U)
        for i, u in enumerate(units):
            ok = np.flatnonzero(np.isfinite(u.y))
            if not len(ok):
                continue
            j = ok[-1]
            self.y_last[i] = u.y[j]
            with np.errstate(divide="ignore"):
                self.lx_last[i] = math.log(u.E[j] / E_ref) if u.E[j] > 0 else -np.inf
            self.ymax[i], self.ymin[i] = np.max(u.y[ok]), np.min(u.y[ok])
            if np.isfinite(self.lhi[i]) and u.discrete:
                self.nf[i] = max(1.0, float(u.events.failure - u.t[j]))
        self.idx = np.concatenate(idx).astype(int)
        self.y = np.concatenate(ys)
        self.lx = np.concatenate(lx)
        self.link = np.concatenate(link).astype(bool)
        self.n = np.bincount(self.idx, minlength=self.U).astype(float)
        self.n_start = np.bincount(self.idx, (~self.link).astype(float), self.U)  # chain starts per unit
        self.qi, self.qu = np.array(qi, int), np.array(qu, int)
        self.qx, self.qv = np.array(qx, float), np.array(qv, float)
        self.quantities = list(quantities or [])
        self._b = None

    def set_b(self, b: float, rho: float = 0.0) -> None:
        """Sufficient statistics of the prewhitened series (AR(1) residuals with coefficient rho):
        u_j = y_j - rho y_{j-1}, offset regressor g_j = 1 - rho, latent regressor X_j - rho X_{j-1}; at a
        chain start sqrt(1 - rho^2) times y_j, 1, X_j."""
        if (b, rho) == self._b:
            return
        if self.path != "power":
            return self._set_b_paris(b, rho)
        X = np.exp(b * self.lx)
        k0 = math.sqrt(1.0 - rho * rho)
        L = self.link
        yp = np.concatenate([[0.0], self.y[:-1]])
        Xp = np.concatenate([[0.0], X[:-1]])
        u = np.where(L, self.y - rho * yp, k0 * self.y)
        xt = np.where(L, X - rho * Xp, k0 * X)
        g = np.where(L, 1.0 - rho, k0)
        bc = lambda w: np.bincount(self.idx, w, self.U)  # noqa: E731
        self.Sgg, self.Sgu, self.SgX = bc(g * g), bc(g * u), bc(g * xt)
        self.Suu, self.SuX, self.SXX = bc(u * u), bc(u * xt), bc(xt * xt)
        self.qX = np.exp(b * self.qx)
        self.rho = rho
        self._b = (b, rho)

    def _set_b_paris(self, b: float, rho: float) -> None:
        """Paris path: the latent regressor depends on z (not linear in r), so only the z-free sums are cached;
        :meth:`_zstats` sums the rest per unit and grid point."""
        k0 = math.sqrt(1.0 - rho * rho)
        L = self.link
        yp = np.concatenate([[0.0], self.y[:-1]])
        u = np.where(L, self.y - rho * yp, k0 * self.y)
        g = np.where(L, 1.0 - rho, k0)
        bc = lambda w: np.bincount(self.idx, w, self.U)  # noqa: E731
        self.Sgg, self.Sgu, self.Suu = bc(g * g), bc(g * u), bc(u * u)
        self._pg, self._pu = g, u
        self._records()
        self._zc = None
        self.rho = rho
        self._b = (b, rho)

    def _records(self) -> None:
        """z-free structure of the records, built once (kept across b, rho): the per-unit sum operator, the
        chain starts and each unit's largest log exposure."""
        if getattr(self, "_sum", None) is not None:
            return
        N = len(self.idx)
        ends = np.searchsorted(self.idx, np.arange(self.U + 1))
        # per-unit sums as one sparse (units x records) product: each unit's records summed in order, with
        # no other unit's values in its sum (a running sum across units would lose the digits of a unit
        # next to one near its blow-up)
        self._sum = sparse.csr_matrix((np.ones(N), np.arange(N), ends), shape=(self.U, N))
        self._starts = np.flatnonzero(~self.link)
        self._lxmax = np.full(self.U, -np.inf)  # largest log exposure per unit (the record nearest blow-up)
        np.maximum.at(self._lxmax, self.idx, self.lx)

    def _hstats(self, z: np.ndarray, th: dict, b: float, gain: bool = False):
        """Level-dependent HI noise (``log_kappa`` in ``th``): record j's residual has the scale
        ``sigma s_j``, ``s_j = sqrt(1 + kappa^2 L_j^2)`` with ``L_j`` the latent path at that record and z, and
        the standardised residuals ``e_j / s_j`` are the AR(1) chain. Prewhitened per record and grid point:
        u = y/s - rho y'/s', g = 1/s - rho/s', x~ = L/s - rho L'/s' (at a chain start sqrt(1 - rho^2) times
        y/s, 1/s, L/s); returns per unit and grid point sum g g, sum g e, sum e e with e = u - a0 g - c x~,
        sum g (u - c x~) (for :meth:`a_post`), sum ln s_j (the Jacobian of the scaling) and whether a record
        lies past a crack-growth path's blow-up.

        ``gain`` (the per-unit HI gain, ``log_sg`` in ``th``): also the latent regressor x~ (L/s prewhitened) and
        the sums x~ x~, g x~, x~ e, appended to the tuple; without ``log_kappa`` the scale s is 1 (constant noise)."""
        self._records()
        rho = math.tanh(th.get("atanh_rho", 0.0))
        kap = math.exp(th["log_kappa"]) if "log_kappa" in th else 0.0
        key = (id(z), z.shape, tuple(sorted(th.items())), b, gain)
        hc = getattr(self, "_hc", None)
        if hc is not None and hc[0] == key and hc[1] is z:
            return hc[2]
        shp = (len(self.idx), z.shape[1])
        nv = 7 if gain else 4
        buf = self._hbuf if getattr(self, "_hbuf", None) is not None and self._hbuf[0].shape == shp \
            and self._hbuf[3].shape[1] == nv else None
        if buf is None:  # work arrays kept between calls (same grid size)
            buf = self._hbuf = (np.empty(shp), np.empty(shp), np.empty(shp), np.empty((shp[0], nv, shp[1])),
                                np.empty(shp) if gain else None, np.empty(shp) if gain else None)
        A, B, C, V, D, Ex = buf
        if self.path == "power":  # L = exp(z) (E/E_ref)^b, in place
            np.take(np.exp(z), self.idx, axis=0, out=A)
            A *= np.exp(b * self.lx)[:, None]
        else:
            with np.errstate(over="ignore", invalid="ignore"):
                A[:] = _path_L(self.path, np.take(z, self.idx, axis=0), self.lx[:, None], th)
        np.minimum(A, 1e150, out=A)  # (a crack-growth path near its blow-up: finite; such z are dropped below)
        if gain:
            D[:] = A  # L, scaled by 1 / s below
        np.multiply(A, kap, out=B)
        B *= B  # (kappa L)^2 (_level_var, in place)
        np.log1p(B, out=V[:, 3])
        V[:, 3] *= 0.5  # ln s
        B += 1.0
        np.sqrt(B, out=B)
        np.reciprocal(B, out=B)  # 1 / s
        A *= -th["c"]
        A += (self.y - th["a0"])[:, None]
        A *= B  # (y - a0 - c L) / s: the standardised residual at a = a0
        k0 = math.sqrt(1.0 - rho * rho)
        st = self._starts
        # prewhiten along each unit's chains: e (residual) into C, g (offset regressor 1/s) into A
        np.multiply(A[:-1], rho, out=C[1:])
        np.subtract(A[1:], C[1:], out=C[1:])
        C[st] = k0 * A[st]
        np.multiply(B[:-1], rho, out=A[1:])
        np.subtract(B[1:], A[1:], out=A[1:])
        A[st] = k0 * B[st]
        np.multiply(A, A, out=V[:, 0])
        np.multiply(A, C, out=V[:, 1])
        np.multiply(C, C, out=V[:, 2])
        if gain:  # x~ = L/s prewhitened into Ex: sums x~ x~, g x~, x~ e
            D *= B
            np.multiply(D[:-1], rho, out=Ex[1:])
            np.subtract(D[1:], Ex[1:], out=Ex[1:])
            Ex[st] = k0 * D[st]
            np.multiply(Ex, Ex, out=V[:, 4])
            np.multiply(A, Ex, out=V[:, 5])
            np.multiply(Ex, C, out=V[:, 6])
        N, n = shp
        S = (self._sum @ V.reshape(N, -1)).reshape(self.U, nv, n)
        blown = (np.exp(z + self._lxmax[:, None]) >= _PARIS_UMAX) if self.path != "power" else \
            np.zeros(z.shape, bool)
        # sum g (u - c x~) = sum g e + a0 sum g g
        out = (S[:, 0], S[:, 1], S[:, 2], S[:, 1] + th["a0"] * S[:, 0], S[:, 3], blown)
        if gain:
            out = out + (S[:, 4], S[:, 5], S[:, 6])
        self._hc = (key, z, out)
        return out

    def _zstats(self, z: np.ndarray, th: dict, resid: bool = True):
        """Per unit and grid point, x~ the prewhitened latent path (Paris): sum g x~ and, with ``resid``, the
        sums of g e and e^2 of the residual e = u - a0 g - c x~ (summed directly: the expanded quadratic
        cancels catastrophically where the path nears its blow-up), and whether a record lies past the
        blow-up. One pass over a (records x grid) array, in place; sum g x~ is kept for :meth:`a_post` at
        the same z."""
        rho, p, D0 = self.rho, math.exp(th["log_b"]), math.exp(-th.get("log_D0", 0.0))
        key = (p, D0, rho)
        zc = self._zc
        if not resid and zc is not None and zc[0] is z and zc[1] == key:
            return zc[2]
        # X = h(exp(z + lx)) / D0 (the arithmetic of _paris_h, in place)
        shp = (len(self.idx), z.shape[1])
        buf = self._zbuf if getattr(self, "_zbuf", None) is not None and self._zbuf[0].shape == shp else None
        if buf is None:  # work arrays kept between calls (same grid size): no new pages per evaluation
            buf = self._zbuf = (np.empty(shp), np.empty((shp[0], 3, shp[1])))
        X = np.take(z, self.idx, axis=0, out=buf[0])
        X += self.lx[:, None]
        np.exp(X, out=X)
        np.minimum(X, _PARIS_UMAX, out=X)
        np.negative(X, out=X)
        np.log1p(X, out=X)
        X *= -p
        np.expm1(X, out=X)
        X *= D0
        N, n = X.shape
        V = buf[1] if resid else buf[1][:, :1]
        xt = V[:, 0]  # prewhitened: X_j - rho X_(j-1) in a chain, sqrt(1 - rho^2) X_j at a chain start
        np.multiply(X[:-1], rho, out=xt[1:])
        np.subtract(X[1:], xt[1:], out=xt[1:])
        st = self._starts
        xt[st] = math.sqrt(1.0 - rho * rho) * X[st]
        g = self._pg[:, None]
        if resid:
            res = V[:, 2]  # e = (u - a0 g) - c x~
            np.multiply(xt, th["c"], out=X)
            np.subtract(self._pu[:, None] - th["a0"] * g, X, out=res)
            np.multiply(g, res, out=V[:, 1])
            np.multiply(res, res, out=res)
        np.multiply(g, xt, out=xt)
        S = (self._sum @ V.reshape(N, -1)).reshape(self.U, -1, n)
        Sgx = S[:, 0]
        self._zc = (z, key, Sgx)
        if not resid:
            return Sgx
        blown = np.exp(z + self._lxmax[:, None]) >= _PARIS_UMAX  # a record past the blow-up: impossible path
        return Sgx, S[:, 1], S[:, 2], blown

    def logf(self, z: np.ndarray, th: dict, b: float, insp: dict) -> np.ndarray:
        """log of prior(z) p(y|z) p(insp|z) P(event|z), z of shape (U, n)."""
        rho = math.tanh(th.get("atanh_rho", 0.0))
        self.set_b(b, rho)
        s, sa, sig, sD = (math.exp(th.get(k, 0.0)) for k in ("log_s", "log_sa", "log_sigma", "log_sD"))
        mu, c, a0 = th["mu"], th["c"], th["a0"]
        r = np.exp(z)
        f = -0.5 * ((z - mu) / s) ** 2 - math.log(s) - 0.5 * _LOG2PI
        n = self.n[:, None]
        het = "log_kappa" in th  # level-dependent noise: the sums depend on z per record (_hstats)
        if "log_sg" in th:  # per-unit HI gain: (offset, gain) marginalised together
            f = f + self._gain_terms(z, th, b, sa, sig, rho)
        # residual e = u - a0 g - c r x~ of the prewhitened series; offset a - a0 ~ N(0, s_a^2) marginalised
        elif het:
            Sgg, Sge, See, _, Slog, blown = self._hstats(z, th, b)
        elif self.path == "power":
            Sw = (self.Suu - 2 * a0 * self.Sgu + a0 * a0 * self.Sgg)[:, None]
            Sge = (self.Sgu - a0 * self.Sgg)[:, None] - c * r * self.SgX[:, None]
            Swx = (self.SuX - a0 * self.SgX)[:, None]
            See = Sw - 2 * c * r * Swx + c * c * r * r * self.SXX[:, None]
        else:
            _, Sge, See, blown = self._zstats(z, th)
        if "log_sg" not in th:
            v2 = sig * sig
            if not het:
                Sgg = self.Sgg[:, None]
            f = f - 0.5 * n * (_LOG2PI + math.log(v2)) - 0.5 * np.log1p(Sgg * sa * sa / v2) \
                - 0.5 / v2 * (See - sa * sa / (v2 + Sgg * sa * sa) * Sge * Sge if self.path == "power" and not het
                              else np.maximum(See - sa * sa / (v2 + Sgg * sa * sa) * Sge * Sge, 0.0)) \
                + 0.5 * self.n_start[:, None] * math.log(1.0 - rho * rho)  # Jacobian of the chain starts
            if het:
                f = f - Slog  # Jacobian of the record scales s_j
            if self.path != "power" or het:
                f = np.where(blown, -np.inf, f)
        for j, q in enumerate(self.quantities):
            m = insp.get(q)
            sel = self.qi == j
            if m is None or not sel.any():
                continue
            tau = math.exp(m["log_tau"])
            rows = self.qu[sel]
            Lq = r[rows] * self.qX[sel, None] if self.path == "power" else \
                _path_L(self.path, z[rows], self.qx[sel, None], th)
            term = -0.5 * ((self.qv[sel, None] - m["alpha"] - m["beta"] * Lq) / tau) ** 2 \
                - math.log(tau) - 0.5 * _LOG2PI
            np.add.at(f, rows, term)
        if "log_sY" in th:  # failure threshold on the observable HI
            return f + self._obs_event_terms(z, r, th, b, rho, sa, sig, c, a0)
        fl = np.isfinite(self.lhi)
        if self.path != "power":
            if fl.any():  # (both ends past the blow-up clip: probability 0, log -inf)
                with np.errstate(divide="ignore"):
                    f[fl] += _log_diff_ndtr(_path_logL(self.path, z[fl], self.llo[fl, None], th) / sD,
                                            _path_logL(self.path, z[fl], self.lhi[fl, None], th) / sD)
            ce = np.isfinite(self.lcens)
            if ce.any():
                f[ce] += special.log_ndtr(-_path_logL(self.path, z[ce], self.lcens[ce, None], th) / sD)
            return f
        if fl.any():
            f[fl] += _log_diff_ndtr((z[fl] + b * self.llo[fl, None]) / sD, (z[fl] + b * self.lhi[fl, None]) / sD)
        ce = np.isfinite(self.lcens)
        if ce.any():
            f[ce] += special.log_ndtr(-(z[ce] + b * self.lcens[ce, None]) / sD)
        return f

    def _gain_terms(self, z: np.ndarray, th: dict, b: float, sa: float, sig: float, rho: float) -> np.ndarray:
        """log p(y | z) with a per-unit HI gain: ``y = a_i + c (1 + g_i) L + e``, ``g_i ~ N(0, s_g^2)`` (``log_sg``)
        besides the offset ``a_i ~ N(a0, s_a^2)``; both marginalised in closed form. With the prewhitened
        regressors G = [g, x~] (offset, latent path; scaled by 1/s under the level noise) and the residual e at
        the prior means, p(y | z) = N(e; 0, sigma^2 I + G P G'), P = diag(s_a^2, (c s_g)^2): by Woodbury
        -n/2 ln(2 pi sigma^2) - 1/2 ln det(I + P G'G / sigma^2) - 1/2 (e'e - q' M^-1 q / sigma^2) / sigma^2
        with M = P^-1 + G'G / sigma^2, q = G'e; plus the chain starts' and the scales' Jacobians."""
        Sgg, Sge, See, _, Slog, blown, Sxx, Sgx, Sxe = self._hstats(z, th, b, gain=True)
        v2 = sig * sig
        pa, pc = sa * sa, (th["c"] * math.exp(th["log_sg"])) ** 2
        M11, M12, M22 = 1.0 / pa + Sgg / v2, Sgx / v2, 1.0 / pc + Sxx / v2
        q1, q2 = Sge / v2, Sxe / v2
        # (a crack-growth path next to its blow-up overflows here: nan / inf, that z dropped as impossible below)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            det = M11 * M22 - M12 * M12
            quad = (M22 * q1 * q1 - 2.0 * M12 * q1 * q2 + M11 * q2 * q2) / det
            f = -0.5 * self.n[:, None] * (_LOG2PI + math.log(v2)) - 0.5 * (np.log(det) + math.log(pa * pc)) \
                - 0.5 * np.maximum(See / v2 - quad, 0.0) \
                + 0.5 * self.n_start[:, None] * math.log(1.0 - rho * rho) - Slog
        return np.where(blown | ~(det > 0) | ~np.isfinite(f), -np.inf, f)

    def a_post(self, r: np.ndarray, th: dict, b: float, z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and variance of the unit offsets ``a_i`` given the HI record and ``r = exp(z)``
        (conjugate normal: prewhitened regression u = a g + c r x~ + N(0, sigma^2), prior N(a0, s_a^2))."""
        rho = math.tanh(th.get("atanh_rho", 0.0))
        self.set_b(b, rho)
        sa, sig = math.exp(th["log_sa"]), math.exp(th["log_sigma"])
        if "log_kappa" in th:  # level-dependent noise: z-dependent sums (_hstats)
            Sgg, _, _, Sgw, _, _ = self._hstats(np.log(r) if z is None else z, th, b)
            prec = 1.0 / sa ** 2 + Sgg / sig ** 2
            m = (th["a0"] / sa ** 2 + Sgw / sig ** 2) / prec
            return m, 1.0 / prec
        prec = 1.0 / sa ** 2 + self.Sgg[:, None] / sig ** 2
        cRgX = th["c"] * r * self.SgX[:, None] if self.path == "power" else \
            th["c"] * self._zstats(np.log(r) if z is None else z, th, resid=False)
        m = (th["a0"] / sa ** 2 + (self.Sgu[:, None] - cRgX) / sig ** 2) / prec
        return m, np.broadcast_to(1.0 / prec, m.shape)

    def _obs_event_terms(self, z, r, th, b, rho, sa, sig, c, a0) -> np.ndarray:
        """log P(event | z, HI record) for a threshold Y ~ N(Y0, s_Y^2) on the observable HI (crossed in the
        direction of c): failure = the unrecorded HI at the failure time, y_f (normal given z: offset posterior,
        AR(1) residual carried from the last record), is past Y while every record was not, P(M < Y <= y_f)
        ~ Phi((m_f - Y0) / sqrt(s_Y^2 + v_f)) - Phi((M - Y0) / s_Y) (oriented; M = the record's extreme);
        censored = P(Y > M)."""
        out = np.zeros_like(z)
        sg = 1.0 if c >= 0 else -1.0
        Y0, sY = th["Y0"], math.exp(th["log_sY"])
        M = (self.ymax if sg > 0 else -self.ymin)[:, None]
        fl = np.isfinite(self.lhi)
        if fl.any():
            ma, va = self.a_post(r, th, b, z)
            ma, va = ma[fl], va[fl]
            rn = (rho ** self.nf[fl])[:, None]
            if "log_kappa" in th:
                # level-dependent noise: the standardised residual e/s carries on from the last record, so the
                # residual at the failure time has mean (s_f / s_k) rn e_k and variance s_f^2 sigma^2 (1 - rn^2)
                # / (1 - rho^2)
                Lf = _path_L(self.path, z[fl], self.lhi[fl, None], th)
                Lk = _path_L(self.path, z[fl], self.lx_last[fl, None], th)
                kap = math.exp(th["log_kappa"])
                sf2 = _level_var(kap, Lf)
                q = rn * np.sqrt(sf2 / _level_var(kap, Lk))
                mf = ma * (1 - q) + c * (Lf - q * Lk) + q * self.y_last[fl, None]
                vf = (1 - q) ** 2 * va + sf2 * sig * sig * (1 - rn * rn) / (1 - rho * rho)
            elif self.path == "power":
                Xf = np.exp(b * self.lhi[fl])[:, None]
                Xk = np.exp(b * self.lx_last[fl])[:, None]
                mf = ma * (1 - rn) + c * r[fl] * (Xf - rn * Xk) + rn * self.y_last[fl, None]
            else:
                Lf = _path_L(self.path, z[fl], self.lhi[fl, None], th)
                Lk = _path_L(self.path, z[fl], self.lx_last[fl, None], th)
                mf = ma * (1 - rn) + c * (Lf - rn * Lk) + rn * self.y_last[fl, None]
            if "log_kappa" not in th:
                vf = (1 - rn) ** 2 * va + sig * sig * (1 - rn * rn) / (1 - rho * rho)
            if self.crossing:
                # the failure time is the time the measured HI reached the unit's level: density of that
                # crossing time, p(Y_i = y(t_f)) |dy/dt| (Jacobian in log exposure; the exposure rate is data)
                vt = sY * sY + vf
                if self.path == "power":
                    dL = b * r[fl] * np.exp(b * self.lhi[fl])[:, None]
                else:
                    uf = np.minimum(np.exp(z[fl] + self.lhi[fl, None]), _PARIS_UMAX)
                    dL = b * uf * np.exp((-b - 1.0) * np.log1p(-uf)) * math.exp(-th.get("log_D0", 0.0))
                with np.errstate(divide="ignore"):
                    out[fl] = -0.5 * (mf - Y0) ** 2 / vt - 0.5 * np.log(2 * math.pi * vt) + np.log(abs(c) * dL)
            else:
                al = (sg * mf - sg * Y0) / np.sqrt(sY * sY + vf)
                be = (M[fl] - sg * Y0) / sY  # (units, 1): one value per unit
                out[fl] = _log_sub_ndtr(al, be)
        ce = np.isfinite(self.lcens)
        if ce.any():
            out[ce] += special.log_ndtr((sg * Y0 - M[ce]) / sY)
        return out

    def grid(self, th: dict, b: float, insp: dict, n: int = 161, windows: np.ndarray | None = None):
        """Per-unit adaptive grids holding the integrand's mass: (z, log f, dz), shapes (U, n), (U, n), (U,).

        ``windows`` (U x 2, updated in place; NaN = none) starts from a previous call's ranges."""
        s = math.exp(th["log_s"])
        wlo, whi = th["mu"] - 9 * s - 1.0, th["mu"] + 9 * s + 1.0
        lo, hi = np.full(self.U, wlo), np.full(self.U, whi)
        if windows is not None:
            ok = np.isfinite(windows[:, 0])
            w = 0.5 * (windows[ok, 1] - windows[ok, 0])
            lo[ok], hi[ok] = windows[ok, 0] - w, windows[ok, 1] + w
        todo = np.ones(self.U, bool)
        lin = np.linspace(0.0, 1.0, n)
        Z = np.zeros((self.U, n))
        F = np.zeros((self.U, n))
        ar = np.arange(n)
        for _ in range(10):
            rows = np.flatnonzero(todo)
            if not len(rows):
                break
            z = lo[rows, None] + (hi - lo)[rows, None] * lin
            # (Paris: the whole batch itself when every unit is on the list: its z-free structure is kept)
            sub = self if self.path != "power" and len(rows) == self.U else _SubBatch(self, rows)
            f = sub.logf(z, th, b, insp)
            f = np.where(np.isfinite(f), f, -np.inf)
            Z[rows], F[rows] = z, f
            mx = f.max(1)
            keep = f > (mx - 40.0)[:, None]
            first = np.argmax(keep, 1)
            last = n - 1 - np.argmax(keep[:, ::-1], 1)
            edge = ((first == 0) & (lo[rows] > wlo)) | ((last == n - 1) & (hi[rows] < whi))
            narrow = (last - first + 2 < 40) & ~edge
            i0, i1 = np.maximum(first - 1, 0), np.minimum(last + 1, n - 1)
            zr = z[ar[None, :] == i0[:, None]], z[ar[None, :] == i1[:, None]]
            if windows is not None:
                windows[rows, 0], windows[rows, 1] = zr
            r_e, r_n = rows[edge], rows[narrow]
            lo[r_e], hi[r_e] = np.minimum(lo[r_e], wlo), np.maximum(hi[r_e], whi)
            lo[r_n], hi[r_n] = zr[0][narrow], zr[1][narrow]
            todo[:] = False
            todo[r_e] = True
            todo[r_n] = True
            todo[rows[~np.isfinite(mx)]] = False
        return Z, F, Z[:, 1] - Z[:, 0]


def _log_sub_ndtr(al: np.ndarray, be: np.ndarray) -> np.ndarray:
    """log(Phi(al) - Phi(be)), floored at log(1e-300) where al <= be (stable in both tails). ``be`` may have
    fewer elements than ``al`` (one per row): its terms are evaluated once per element of ``be``."""
    al, be = np.asarray(al, float), np.asarray(be, float)
    shape = np.broadcast_shapes(al.shape, be.shape)
    al = np.broadcast_to(al, shape)
    up_b = be > 0
    with np.errstate(divide="ignore", invalid="ignore"):  # each branch only where it is used
        s_be = np.where(up_b, np.exp(special.log_ndtr(-be)), special.ndtr(be))  # Phi(-be) or Phi(be)
        up = np.broadcast_to(up_b, shape)
        s_be = np.broadcast_to(s_be, shape)
        d = np.empty(shape)
        d[up] = s_be[up] - np.exp(special.log_ndtr(-al[up]))
        lo = ~up
        d[lo] = special.ndtr(al[lo]) - s_be[lo]
        return np.log(np.maximum(d, 1e-300))


class _SubBatch(_Batch):
    """A view of some rows of a batch (same arrays, selected units)."""

    def __init__(self, base: _Batch, rows: np.ndarray):  # noqa: D401 - light view, no parent __init__
        self.U = len(rows)
        self.n, self.n_start = base.n[rows], base.n_start[rows]
        self._base, self._rows = base, rows
        self.llo, self.lhi, self.lcens = base.llo[rows], base.lhi[rows], base.lcens[rows]
        self.y_last, self.lx_last, self.nf = base.y_last[rows], base.lx_last[rows], base.nf[rows]
        self.ymax, self.ymin = base.ymax[rows], base.ymin[rows]
        self.quantities = base.quantities
        pos = np.full(base.U, -1)
        pos[rows] = np.arange(len(rows))
        m = pos[base.qu] >= 0 if len(base.qu) else np.zeros(0, bool)
        self.qi, self.qu, self.qx, self.qv = base.qi[m], pos[base.qu[m]], base.qx[m], base.qv[m]
        self.path = base.path
        self.crossing = base.crossing
        # the records of these units (z-dependent sums are per record: Paris path, level-dependent noise)
        rec = pos[base.idx] >= 0
        self.idx, self.lx, self.link, self.y = pos[base.idx[rec]], base.lx[rec], base.link[rec], base.y[rec]
        self._b = None

    def set_b(self, b: float, rho: float = 0.0) -> None:
        if self.path != "power":
            return _Batch.set_b(self, b, rho)
        B = self._base
        B.set_b(b, rho)
        r = self._rows
        self.Sgg, self.Sgu, self.SgX = B.Sgg[r], B.Sgu[r], B.SgX[r]
        self.Suu, self.SuX, self.SXX = B.Suu[r], B.SuX[r], B.SXX[r]
        self.qX = np.exp(b * self.qx)


def _hessian(f, x: np.ndarray, f0: float, h: float) -> np.ndarray:
    """Central finite-difference Hessian of ``f`` at ``x`` (step ``h`` in every coordinate)."""
    d = len(x)
    H = np.zeros((d, d))
    E = np.eye(d) * h
    fp = np.array([f(x + E[i]) for i in range(d)])
    fm = np.array([f(x - E[i]) for i in range(d)])
    for i in range(d):
        H[i, i] = (fp[i] - 2.0 * f0 + fm[i]) / (h * h)
        for j in range(i):
            H[i, j] = H[j, i] = (f(x + E[i] + E[j]) - f(x + E[i] - E[j]) - f(x - E[i] + E[j])
                                 + f(x - E[i] - E[j])) / (4.0 * h * h)
    return H


#: the box of the noise parameters in nll (|atanh rho| < 3: rho < 0.995; -9 < log kappa < 5)
NOISE_BOX = {"atanh_rho": (-3.0, 3.0), "log_kappa": (-9.0, 5.0)}


def _in_noise_box(th: dict) -> bool:
    """Whether the noise parameters of ``th`` (rho always, kappa with the level-dependent noise) lie inside
    :data:`NOISE_BOX`: the one place of those bounds for the likelihood and for :func:`_noise_regularity`."""
    return all(lo < th[k] < hi for k, (lo, hi) in NOISE_BOX.items() if k == "atanh_rho" or k in th)


def _noise_regularity(nll, x: np.ndarray, names: list[str], h: float = 3e-3, z: float = 1.959963984540054) -> dict:
    """Whether a level-noise fit's maximum is regular enough for AIC to compare it with the constant noise.

    AIC (and the likelihood-ratio test it approximates) assumes the maximum-likelihood estimate is an interior
    point of the parameter space, locally identified, and asymptotically normal there (Self & Liang 1987: on a
    boundary the penalty 2k no longer holds). Checked at the optimum ``x`` (the optimiser's coordinates, where
    ``atanh_rho`` and ``log_kappa`` are unscaled): (1) no neighbour at the finite-difference step ``h`` along a
    noise parameter lies outside the parameter space (``nll`` = 1e30: the optimum sits on a bound, e.g. rho at
    0.995); (2) the profile observed information of the noise parameters (sigma, kappa, rho: the Schur complement
    of the others' block of the finite-difference Hessian of ``nll``, over the directions that block identifies;
    a boundary the constant fit shares, such as a threshold scatter at 0, is held fixed) is positive definite
    (a flat direction is an unidentified combination, e.g. sigma -> 0 with kappa -> infinity when the noise is
    all proportional to L); (3) the Wald 95 % interval of each noise parameter (rho, kappa) lies
    inside its box (:data:`NOISE_BOX`): an interval reaching the box is a likelihood not bounded away from the
    boundary, where the normal approximation fails (sd from the inverse profile information). Returns
    {"regular", "reason", "wald": {name: [lo, hi]}, "hessian_eigen_min"} (the profile information's).
    The box of log kappa (kappa < 148: the noise 148 times its level-0 value at the median threshold) is a
    numerical limit, not a physical one: (3) asks that the likelihood bound kappa away from it."""
    f0 = float(nll(x))
    d = len(x)
    E = np.eye(d) * h
    jn = [names.index(k) for k in ("log_sigma", "log_kappa", "atanh_rho") if k in names]
    for i in jn:
        if nll(x + E[i]) >= 1e29 or nll(x - E[i]) >= 1e29:
            return {"regular": False, "reason": f"optimum within {h:g} of a bound of {names[i]}"}
    H = _hessian(nll, x, f0, h)
    H = 0.5 * (H + H.T)
    if not np.all(np.isfinite(H)):
        return {"regular": False, "reason": "observed information not finite"}
    # the noise parameters' profile information: Schur complement of the other parameters' block over the
    # directions that block identifies (positive curvature); its own flat or boundary directions (a threshold
    # scatter at 0, shared with the constant fit) are held fixed: they are not the noise model's question
    jr = [j for j in range(d) if j not in jn]
    w, V = np.linalg.eigh(0.5 * (H[np.ix_(jr, jr)] + H[np.ix_(jr, jr)].T))
    keep = w > 0
    Hrr_inv = (V[:, keep] / w[keep]) @ V[:, keep].T
    S = H[np.ix_(jn, jn)] - H[np.ix_(jn, jr)] @ Hrr_inv @ H[np.ix_(jr, jn)]
    S = 0.5 * (S + S.T)
    ev = np.linalg.eigvalsh(S)
    if ev.min() <= 0:
        return {"regular": False, "reason": f"profile information of the noise parameters not positive definite "
                                            f"(smallest eigenvalue {ev.min():.3g}: a direction the records do not "
                                            "identify)", "hessian_eigen_min": float(ev.min())}
    sd = np.sqrt(np.diag(np.linalg.inv(S)))
    wald, bad = {}, []
    for k, (lo, hi) in NOISE_BOX.items():
        if k in names:
            j = names.index(k)
            sj = sd[jn.index(j)]
            wald[k] = [float(x[j] - z * sj), float(x[j] + z * sj)]
            if wald[k][0] <= lo or wald[k][1] >= hi:
                bad.append(f"{k} Wald 95 % interval [{wald[k][0]:.3g}, {wald[k][1]:.3g}] reaches its bound "
                           f"({lo:g}, {hi:g})")
    return {"regular": not bad, "reason": "; ".join(bad) or "interior, positive-definite information",
            "wald": wald, "hessian_eigen_min": float(ev.min())}


def _mvt_logpdf(X: np.ndarray, m: np.ndarray, L: np.ndarray, dof: float) -> np.ndarray:
    """Log density of the multivariate Student-t with location m, scale L L^T, ``dof`` at the rows of X."""
    d = len(m)
    q = np.sum(np.linalg.solve(L, (X - m).T) ** 2, axis=0)
    return (special.gammaln(0.5 * (dof + d)) - special.gammaln(0.5 * dof) - 0.5 * d * math.log(dof * math.pi)
            - float(np.sum(np.log(np.abs(np.diag(L))))) - 0.5 * (dof + d) * np.log1p(q / dof))


def _posterior_draws(nlp, x_hat: np.ndarray, n_draws: int, rng: np.random.Generator, n_proposals: int = 400,
                     dof: float = 5.0, h: float = 3e-3, max_rounds: int = 5) -> tuple[list[np.ndarray], dict]:
    """Draws from the posterior of the population parameters, ``exp(-nlp)`` (log likelihood + log prior, in
    the fit's scaled coordinates), by adaptive multiple importance sampling (AMIS, Cornuet et al. 2012):

    1. Laplace approximation at the posterior mode (finite-difference Hessian) as a multivariate Student-t
       proposal (``dof``; heavier tails than the Gaussian so the weights stay bounded);
    2. while the effective sample size is below ``2 n_draws`` (a posterior far from Gaussian, e.g. a ridge),
       a new Student-t proposal from the weighted mean and covariance of all samples so far, every sample
       re-weighted against the equal mixture of all proposals used (deterministic multiple mixture);
    3. ``n_draws`` by systematic resampling.

    A fleet of a handful of units leaves the population parameters (rate scatter, threshold scatter, shape)
    uncertain, and the maximum-likelihood scatter of a few units is biased low, often to 0 (a boundary
    estimate); the point estimate then gives intervals that are too narrow. Mixing the prognosis over these
    draws is the posterior predictive. Returns the draws and a summary (effective sample size...)."""
    r = optimize.minimize(nlp, x_hat, method="L-BFGS-B", options={"maxiter": 200, "eps": 1e-6})
    f_hat = nlp(x_hat)
    x_map, f_map = (r.x, float(r.fun)) if np.isfinite(r.fun) and r.fun < f_hat else (x_hat, f_hat)
    H = _hessian(nlp, x_map, f_map, h)
    H = 0.5 * (H + H.T)
    w, V = np.linalg.eigh(H)
    # a flat or numerically non-convex direction gets a unit-scale proposal (the weights then correct it)
    w_used = np.where(np.isfinite(w) & (w > 1.0), w, 1.0)
    S0 = V @ np.diag(1.0 / w_used) @ V.T  # Laplace covariance (floored)
    d = len(x_map)
    props = [(x_map, np.linalg.cholesky(S0 + 1e-12 * np.eye(d)))]
    X = np.zeros((0, d))
    lp = np.zeros(0)
    ess_hist = []
    for rnd in range(max_rounds):
        m, L = props[-1]
        zs = rng.standard_normal((n_proposals, d))
        g = np.sqrt(dof / rng.chisquare(dof, n_proposals))
        Xn = m + (zs * g[:, None]) @ L.T
        if rnd == 0:
            Xn[0] = x_map  # the mode itself is always a candidate
        ln = np.array([-nlp(x) for x in Xn])
        X, lp = np.vstack([X, Xn]), np.concatenate([lp, np.where(np.isfinite(ln) & (ln > -1e29), ln, -np.inf)])
        logq = _lse(np.stack([_mvt_logpdf(X, mm, LL, dof) for mm, LL in props], axis=-1)) - math.log(len(props))
        lw = lp - logq
        lw -= np.max(lw)
        wt = np.exp(lw)
        wt /= wt.sum()
        ess = float(1.0 / np.sum(wt ** 2))
        ess_hist.append(ess)
        if ess >= 2 * n_draws or rnd == max_rounds - 1:
            break
        mu_w = wt @ X
        C = (wt[:, None] * (X - mu_w)).T @ (X - mu_w)
        if ess < d + 1:  # too few effective points for a full covariance: keep the Laplace shape in it
            C = 0.5 * (C + S0)
        C = 0.5 * (C + C.T)
        ev, EV = np.linalg.eigh(C)
        C = EV @ np.diag(np.maximum(ev, 1e-10 * max(float(ev.max()), 1e-300))) @ EV.T
        props.append((mu_w, np.linalg.cholesky(C)))
    u = (rng.uniform() + np.arange(n_draws)) / n_draws  # systematic resampling
    idx = np.minimum(np.searchsorted(np.cumsum(wt), u), len(X) - 1)
    info = {"method": "posterior draws: Laplace at the mode -> adaptive multiple importance sampling "
                      "(Student-t proposals) -> systematic resampling",
            "prior": "uniform on the standard deviations (s, s_a, sigma, s_D, tau) and on rho; flat on the rest",
            "n_draws": int(n_draws), "n_samples": int(len(X)), "rounds": len(props), "ess": ess,
            "ess_per_round": ess_hist, "distinct_draws": int(len(set(idx.tolist()))),
            "laplace_sd": [float(v) for v in np.sqrt(np.diag(S0))],
            "hessian_eigen_min": float(np.min(w)), "map_minus_mle_nlp": float(f_map - f_hat)}
    return [X[i] for i in idx], info


class LifeModel:
    """Fitted population parameters + the prognosis on one unit (see the module docstring)."""

    PARAMS = ("mu", "log_s", "log_b", "c", "a0", "log_sa", "log_sigma", "log_sD", "atanh_rho")
    #: observable threshold: mu fixed at 0 (no latent threshold fixes the latent scale); Y0, log_sY its law
    PARAMS_OBS = ("log_s", "log_b", "c", "a0", "log_sa", "log_sigma", "Y0", "log_sY", "atanh_rho")

    def __init__(self, theta: dict, E_ref: float, exposure: str = "missions", feature: str = "hi",
                 inspections: dict | None = None, fit_info: dict | None = None, time_unit: str = "mission",
                 draws: list | None = None, plug_in: bool = True):
        self.theta = {k: float(v) for k, v in theta.items()}
        # posterior draws of the population parameters ({"theta", "inspections"} each); the prognosis mixes
        # them (parameter uncertainty). plug_in: a point-estimate model widens its threshold law to the
        # Student-t predictive instead (old model files, fits with n_draws=0)
        self.draws = list(draws or [])
        self.plug_in = plug_in
        self.E_ref = float(E_ref)
        self.exposure = exposure
        self.feature = feature
        self.inspections = inspections or {}  # quantity -> {"alpha", "beta", "log_tau"}
        self.fit_info = fit_info or {}
        self.time_unit = time_unit

    # ---- parameters
    @property
    def b(self) -> float:
        return math.exp(self.theta["log_b"])

    @property
    def path(self) -> str:
        """Latent path family: ``power`` or ``paris`` (crack-growth shape; :func:`_path_L`)."""
        return self.fit_info.get("path", "power")

    def L(self, z, E):
        """Latent degradation (1 = median latent threshold) at log rate(s) z and exposure(s) E (broadcast)."""
        with np.errstate(divide="ignore"):
            return _path_L(self.path, z, np.log(np.maximum(E, 0.0) / self.E_ref), self.theta)

    @property
    def threshold(self) -> str:
        """``latent`` or ``observable``: where the failure threshold sits."""
        return "observable" if "log_sY" in self.theta else "latent"

    def latent_scale(self) -> float:
        """Factor on ``exp(z) X`` giving the reported degradation (1 = median failure threshold): 1 for the latent
        threshold; for the observable one the mean path's HI change over the way from the mean offset to the
        median threshold, c / (Y0 - a0)."""
        if self.threshold == "latent":
            return 1.0
        d = (self.theta["Y0"] - self.theta["a0"]) / self.theta["c"]
        return 1.0 / d if d > 0 else 1.0

    def to_json(self, path=None) -> dict:
        d = {"kind": "hdphm life model v1", "theta": self.theta, "E_ref": self.E_ref, "exposure": self.exposure,
             "feature": self.feature, "inspections": self.inspections, "fit_info": self.fit_info,
             "time_unit": self.time_unit, "parameter_draws": self.draws,
             "readable": {"rate_log_mean": self.theta["mu"], "rate_log_std": math.exp(self.theta["log_s"]),
                          "shape_b": self.b, "hi_change_at_median_threshold": self.theta["c"],
                          "hi_offset_mean": self.theta["a0"], "hi_offset_std": math.exp(self.theta["log_sa"]),
                          "hi_noise_std": math.exp(self.theta["log_sigma"]),
                          "threshold": self.threshold,
                          **({"threshold_log_std": math.exp(self.theta["log_sD"])} if self.threshold == "latent"
                             else {"threshold_hi_median": self.theta["Y0"],
                                   "threshold_hi_std": math.exp(self.theta["log_sY"])}),
                          "hi_noise_ar1": math.tanh(self.theta.get("atanh_rho", 0.0)),
                          **({"hi_noise_level_kappa": math.exp(self.theta["log_kappa"])} if "log_kappa" in self.theta
                             else {}),
                          **({"hi_gain_rel_std": math.exp(self.theta["log_sg"])} if "log_sg" in self.theta else {})}}
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Path(path).write_text(json.dumps(d, indent=1, default=float))
        return d

    @classmethod
    def from_json(cls, src) -> "LifeModel":
        if not isinstance(src, dict):
            from hd_bag.files import read_json

            p = Path(src)
            try:
                src = read_json(p, "life-model JSON")
            except OSError as e:  # absent, a directory, unreadable: ValueError as before, naming the path
                raise ValueError(str(e) if isinstance(e, FileNotFoundError)
                                 else f"{p}: not a readable life-model JSON ({e})") from e
            if src.get("kind") != "hdphm life model v1":
                raise ValueError(f"{p}: not a life model written by 'hdphm prognostic fit' (kind {src.get('kind')!r})")
        return cls(src["theta"], src["E_ref"], src.get("exposure", "missions"), src.get("feature", "hi"),
                   src.get("inspections", {}), src.get("fit_info", {}), src.get("time_unit", "mission"),
                   draws=src.get("parameter_draws", []))

    def log_marginal(self, units: list[UnitHistory]) -> np.ndarray:
        """Log marginal likelihood of each unit's record and events under this model."""
        bt = _Batch(units, self.E_ref, quantities=sorted(self.inspections), path=self.path,
                    crossing=self.fit_info.get("failure_at") == "crossing")
        z, f, dz = bt.grid(self.theta, self.b, self.inspections)
        return _lse(f) + np.log(dz)

    # ---- fit
    @classmethod
    def fit(cls, units: list[UnitHistory], exposure: str = "missions", feature: str = "hi",
            time_unit: str = "mission", maxiter: int = 600, progress: bool = False, n_draws: int = 20,
            seed: int = 0, threshold: str = "latent", failure_level: float | None = None,
            path: str = "power", failure_at: str = "interval", exposure_rate: str = "mean",
            exposure_spread: str = "renewal", noise: str = "constant", scale_prior: str = "uniform",
            hi_gain: str = "shared") -> "LifeModel":
        """Maximum likelihood over the units (their HI histories and events); see the module docstring.

        ``threshold``: ``latent`` (failure when the latent degradation crosses D_i), ``observable`` (failure
        when the measured HI crosses Y_i) or ``auto`` (both fitted, the lower AIC kept, i.e. the higher maximum
        likelihood when both have 9 population parameters; the log-likelihoods go to
        ``fit_info["threshold_candidates"]``). ``failure_level``: the HI level that defines failure when the
        failure definition is on the measured HI and its level is known (NASA: 80 % of rated capacity, Virkler:
        49.8 mm): the observable threshold's median Y0 is then fixed there (its scatter s_Y still fitted) instead
        of being estimated from the gap between the last record and the unrecorded value at failure.
        ``n_draws`` posterior draws of the population parameters
        (:func:`_posterior_draws`; 0: point estimate only) carry the parameter uncertainty of a small fleet into
        the prognosis. ``exposure_rate``: how the prognosis extrapolates a unit's exposure to its failure
        exposure, ``mean`` (default: cumulative exposure grows at the mean rate) or ``median`` (the default
        before, kept for models saved without the key) per-step rate of its record (:meth:`UnitHistory.rate`).
        ``exposure_spread``: ``renewal`` (default) draws the time to accrue the remaining exposure from the
        inverse-Gaussian first passage of the unit's i.i.d. per-step increments (:meth:`UnitHistory.rate_var`;
        constant increments unchanged), ``renewal+rate`` also draws each sample's mean rate from its sampling law
        (:meth:`UnitHistory.rate_mean_var`), ``none`` extrapolates at the single rate (models saved without the key).
        ``noise``: the HI noise model, ``constant`` (one sigma), ``level`` (sd ``sigma sqrt(1 + kappa^2 L^2)``,
        ``theta["log_kappa"]``) or ``auto`` (the level model fitted for the path and threshold the constant noise
        chose, the lower AIC kept; ``fit_info["noise"]``, ``fit_info["noise_aic"]``).

        ``path``: the latent path family, ``power`` (``r (E/E_ref)^b``), ``paris`` (crack-growth shape
        ``h(r E/E_ref) / D0``, ``h(u) = (1 - u)^(-p) - 1``: Paris' law with dK ~ sqrt(a) integrated, per-unit
        rate r = the inverse of the unit's blow-up exposure, exponent p = 2/(m-2) shared; one parameter more
        than the power law: D0 with the latent threshold, mu with the observable one) or ``auto`` (every
        family x threshold fitted on these units, the lowest AIC kept; never chosen per scored unit).

        ``failure_at``: ``interval`` (a failure at t_f happened between the last record and t_f: found failed
        at t_f) or ``crossing`` (continuous records, failure defined on the measured HI: t_f is the time the
        measured HI reached the unit's level; its likelihood is the density of that crossing time,
        ``N(Y0; m_f, s_Y^2 + v_f) |dy/dt(t_f)|``, observable threshold only). With ``crossing`` and a
        ``failure_level``, the level in the model's coordinates is also fitted (one parameter more) and the
        lower AIC kept: where the path family's shape is wrong between the last records and the failure level
        (Virkler: no record between 39 mm and the 49.8 mm failure length), the path does not reach the defined
        level at the failure times and a fixed level leaves that bias to the level's scatter s_Y. ``auto``: the
        failure definition decides (:func:`failure_at_rule`: ``crossing`` when ``failure_level`` is given and every
        failed unit's records run through its failure, the record at the failure time being the first at or past
        the level; ``interval`` otherwise); the choice and its reason go to ``fit_info["failure_at_rule"]``.

        ``hi_gain``: ``shared`` (one HI gain c for all units), ``unit`` (per-unit gain ``c (1 + g_i)``,
        ``g_i ~ N(0, s_g^2)``, ``theta["log_sg"]``, marginalised with the offset: :meth:`_Batch._gain_terms`;
        fitted for the path, threshold and noise chosen with the shared gain, from that optimum; latent threshold
        only) or ``auto`` (that fit kept when its AIC is lower); ``fit_info["hi_gain"]``, ``fit_info["gain_aic"]``."""
        if exposure_rate not in ("median", "mean"):
            raise ValueError(f"life-model fit: exposure_rate {exposure_rate!r} is not one of median, mean")
        if exposure_spread not in SPREADS:
            raise ValueError(f"life-model fit: exposure_spread {exposure_spread!r} is not one of {', '.join(SPREADS)}")
        if scale_prior not in SCALE_PRIORS:
            raise ValueError(f"life-model fit: scale_prior {scale_prior!r} is not one of {', '.join(SCALE_PRIORS)}")
        if hi_gain not in GAINS + ("auto",):
            raise ValueError(f"life-model fit: hi_gain {hi_gain!r} is not one of {', '.join(GAINS)}, auto")
        if noise not in NOISES + ("auto",):
            raise ValueError(f"life-model fit: noise {noise!r} is not one of {', '.join(NOISES)}, auto")
        rule = None
        if failure_at == "auto":  # from the failure definition (level + records), never from a score
            failure_at, rule = failure_at_rule(units, failure_level)
            if failure_at == "crossing" and threshold == "latent":
                failure_at, rule = "interval", rule + "; but the latent threshold was asked for: interval"
        if failure_at not in FAILURE_AT:
            raise ValueError(f"life-model fit: failure_at {failure_at!r} is not one of interval, crossing, auto")
        if failure_at == "crossing" and threshold == "latent":
            raise ValueError("life-model fit: failure_at='crossing' needs the observable threshold (failure defined "
                             "on the measured HI)")
        crossing = failure_at == "crossing"
        if crossing:
            threshold = "observable"
        if path not in PATHS + ("auto",):
            raise ValueError(f"life-model fit: path {path!r} is not one of {', '.join(PATHS)}, auto")
        if threshold not in THRESHOLDS + ("auto",):
            raise ValueError(f"life-model fit: threshold {threshold!r} is not one of {', '.join(THRESHOLDS)}, auto")
        units = [u for u in units if len(u.t) >= 2 and np.isfinite(u.y).sum() >= 2]
        if len(units) < 2:
            raise ValueError(f"life-model fit: {len(units)} unit(s) with >= 2 finite health-indicator values; need >= 2")
        nfail = sum(u.events.failure is not None for u in units)
        if nfail < 2:
            raise ValueError(f"life-model fit: {nfail} failure(s) among {len(units)} units: the failure threshold "
                             "is not identifiable without at least 2 failures in the events")
        # exposure scale: median exposure at failure / censoring
        ends = [u.exposure_at(u.events.failure) if u.events.failure is not None else u.E[-1] for u in units]
        E_ref = float(np.median([e for e in ends if e > 0]))
        # start: per-unit least squares y = a_i + m_i X (b = 1)
        m_i, a_i, res, cf, ac, yf = [], [], [], [], [], []
        for u, e in zip(units, ends):
            ok = np.isfinite(u.y)
            X = u.E[ok] / E_ref
            A = np.column_stack([np.ones(ok.sum()), X])
            coef, *_ = np.linalg.lstsq(A, u.y[ok], rcond=None)
            a_i.append(coef[0])
            m_i.append(coef[1])
            res.append(u.y[ok] - A @ coef)
            if len(res[-1]) > 3 and np.std(res[-1]) > 0:
                ac.append(float(np.corrcoef(res[-1][:-1], res[-1][1:])[0, 1]))
            if u.events.failure is not None:
                cf.append(coef[1] * e / E_ref)
                yf.append(float(coef[0] + coef[1] * e / E_ref))  # fitted HI at the failure
        c0 = float(np.median(cf))
        if c0 == 0:
            c0 = float(np.median(m_i)) or 1.0
        rr = np.array(m_i) / c0
        lr = np.log(rr[rr > 0]) if (rr > 0).sum() >= 2 else np.zeros(2)
        sig0 = float(np.std(np.concatenate(res))) or 1e-6
        hi_all = np.concatenate([u.y[np.isfinite(u.y)] for u in units])
        hi_scale = float(np.std(hi_all)) or sig0  # scale of the half-Cauchy prior on HI-unit scatters (< 3 groups)
        theta0 = {"mu": float(np.mean(lr)), "log_s": math.log(max(float(np.std(lr)), 0.05)), "log_b": 0.0,
                  "c": c0, "a0": float(np.mean(a_i)), "log_sa": math.log(max(float(np.std(a_i)), 0.1 * sig0)),
                  "log_sigma": math.log(sig0), "log_sD": math.log(0.2),
                  "atanh_rho": math.atanh(float(np.clip(np.median(ac) if ac else 0.0, -0.9, 0.9)))}
        # inspection maps: quantities with enough inspections
        by_q: dict[str, int] = {}
        for u in units:
            for _, q, _ in u.events.inspections:
                by_q[q] = by_q.get(q, 0) + 1
        notes = [f"inspections of {q!r}: {n} < {MIN_INSPECTIONS}, not used" for q, n in by_q.items()
                 if n < MIN_INSPECTIONS]
        qs = sorted(q for q, n in by_q.items() if n >= MIN_INSPECTIONS)
        insp0 = {}
        for q in qs:  # start: regress the value on the start model's latent path (median unit)
            v = [(x[2], (u.exposure_at(x[0]) / E_ref) * math.exp(theta0["mu"])) for u in units
                 for x in u.events.inspections if x[1] == q]
            V, L = np.array(v).T
            A = np.column_stack([np.ones_like(L), L])
            coef, *_ = np.linalg.lstsq(A, V, rcond=None)
            sd = float(np.std(V - A @ coef)) or abs(float(np.mean(V))) * 0.1 or 1e-6
            insp0[q] = {"alpha": float(coef[0]), "beta": float(coef[1]), "log_tau": math.log(sd)}
        batches = {fam: _Batch(units, E_ref, quantities=qs, path=fam, crossing=crossing) for fam in PATHS}
        lends = np.log(np.array([e for e in ends if e > 0]) / E_ref)
        ik = [f"{q}|{k}" for q in qs for k in ("alpha", "beta", "log_tau")]
        iscale = [max(abs(insp0[q][k]), 1e-9) if k != "log_tau" else 1.0
                  for q in qs for k in ("alpha", "beta", "log_tau")]
        ix0 = [insp0[q][k] for q in qs for k in ("alpha", "beta", "log_tau")]

        def setup(kind, fam="power", fix_level=True, start=None, nz="constant", gain=False):
            """(parameter names, start in the optimiser's coordinates, scale, unpack, nll) of one threshold kind."""
            batch = batches[fam]
            flevel = failure_level if fix_level else None
            if fam == "paris":  # start: p = 1, median unit at u = 1/2 at its end (h = 1), rate scatter of the ends
                names = list(cls.PARAMS if kind == "latent" else cls.PARAMS_OBS)
                yfa = np.array(yf)
                t0 = dict(theta0, mu=math.log(0.5) - float(np.median(lends)), log_b=0.0, c=c0, log_D0=0.0,
                          log_s=math.log(max(float(np.std(lends)), 0.05)),
                          Y0=float(np.median(yfa)), log_sY=math.log(max(float(np.std(yfa)), 0.5 * sig0)))
                scale = {"c": abs(c0), "a0": sig0 + abs(theta0["a0"]) * 0.01, "Y0": sig0 + abs(t0["Y0"]) * 0.01}
                names = names + (["log_D0"] if kind == "latent" else ["mu"])
                if kind == "observable" and flevel is not None:
                    names.remove("Y0")
                scale = [scale.get(k, 1.0) for k in names]
            elif kind == "latent":
                names, t0 = list(cls.PARAMS), dict(theta0)
                scale = [1.0, 1.0, 1.0, abs(c0), sig0 + abs(theta0["a0"]) * 0.01, 1.0, 1.0, 1.0, 1.0]
            else:  # the latent scale is fixed by mu = 0 (no latent threshold): c = median unit's HI change at E_ref
                names = list(cls.PARAMS_OBS)
                yfa = np.array(yf)
                t0 = dict(theta0, c=c0 * math.exp(theta0["mu"]), mu=0.0, Y0=float(np.median(yfa)),
                          log_sY=math.log(max(float(np.std(yfa)), 0.5 * sig0)))
                ysc = sig0 + abs(t0["Y0"]) * 0.01
                scale = [1.0, 1.0, abs(t0["c"]), sig0 + abs(theta0["a0"]) * 0.01, 1.0, 1.0, ysc, 1.0, 1.0]
                if flevel is not None:  # the failure definition's level is known: Y0 is not fitted
                    j = names.index("Y0")
                    names.pop(j)
                    scale.pop(j)
            if nz == "level":  # level-dependent HI noise: kappa (start 1: the noise doubles by L = 1.7)
                names = names + ["log_kappa"]
                scale = scale + [1.0]
                t0 = dict(t0, log_kappa=0.0)
            if gain:  # per-unit HI gain's relative scatter s_g (start 0.1; from a nested optimum: that start too)
                names = names + ["log_sg"]
                scale = scale + [1.0]
                t0 = dict(t0, log_sg=math.log(0.1))
            sc = np.array(scale + iscale)
            if start is not None:  # a nested model's optimum (theta, inspections) as the start
                t0 = dict(t0, **{k: v for k, v in start[0].items() if k in names})
                ix0_ = [start[1][q][k] for q in qs for k in ("alpha", "beta", "log_tau")]
            x0 = np.array([t0[k] for k in names] + (ix0_ if start is not None else ix0)) / sc
            npar = len(names)
            lo_sY = math.log(hi_scale) - 12.0

            def unpack(xs):
                x = xs * sc
                th = dict(zip(names, x[:npar]))
                if kind == "observable" and fam == "power":
                    th["mu"] = 0.0
                if kind == "observable":
                    if flevel is not None:
                        th["Y0"] = float(flevel)
                    th.pop("log_D0", None)
                ins = {q: {k: float(x[npar + 3 * j + i]) for i, k in enumerate(("alpha", "beta", "log_tau"))}
                       for j, q in enumerate(qs)}
                return th, ins

            windows = np.full((len(units), 2), np.nan)

            def nll(xs, fresh=False):  # fresh: grids from the population law, not the last call's windows
                th, ins = unpack(xs)
                if not (-6 < th["log_b"] < 2.5 and -9 < th["log_s"] < 3 and _in_noise_box(th)):
                    return 1e30
                if kind == "latent" and not -9 < th["log_sD"] < 2:
                    return 1e30
                if "log_sg" in th and not -9 < th["log_sg"] < 2:
                    return 1e30
                if kind == "observable" and not lo_sY < th["log_sY"] < lo_sY + 15.0:
                    return 1e30
                if fam == "paris" and not (-12 < th["mu"] < 12 and abs(th.get("log_D0", 0.0)) < 12):
                    return 1e30
                z, f, dz = batch.grid(th, math.exp(th["log_b"]), ins, windows=None if fresh else windows)
                with np.errstate(divide="ignore"):
                    lm = _lse(f) + np.log(dz)
                if not np.all(np.isfinite(lm)):
                    return 1e30
                return -float(lm.sum())

            return names, x0, unpack, nll

        def ml(kind, fam="power", fix_level=True, start=None, nz="constant", gain=False):
            names, xs0, unpack, nll = setup(kind, fam, fix_level, start, nz, gain)
            # quasi-Newton first (finite-difference gradients of a smooth quadrature), then a Nelder-Mead polish
            # (robust where the adaptive grid makes the finite differences noisy)
            r = optimize.minimize(nll, xs0, method="L-BFGS-B", options={"maxiter": 300, "eps": 1e-6})
            x1 = r.x if np.isfinite(r.fun) and r.fun < nll(xs0) else xs0
            r2 = optimize.minimize(nll, x1, method="Nelder-Mead",
                                   options={"maxiter": maxiter, "maxfev": maxiter, "xatol": 1e-4, "fatol": 1e-3,
                                            "adaptive": True})
            return {"names": names, "unpack": unpack, "nll": nll, "r": r, "r2": r2,
                    "aic": 2.0 * (len(names) + 3 * len(qs)) + 2.0 * float(r2.fun)}

        kinds = THRESHOLDS if threshold == "auto" else (threshold,)
        fams = PATHS if path == "auto" else (path,)
        noises = NOISES if noise == "auto" else (noise,)
        allfits = {(f_, k, noises[0]): ml(k, f_, nz=noises[0]) for f_ in fams for k in kinds}
        level_aic = None
        if crossing and failure_level is not None:  # the defined level vs a fitted one (AIC, training units)
            level_aic = {}
            for f_ in fams:
                fx = allfits[(f_, "observable", noises[0])]  # nested: the fitted level starts at the fixed one's optimum
                free = ml("observable", f_, fix_level=False, start=fx["unpack"](fx["r2"].x), nz=noises[0])
                level_aic[(f_, noises[0])] = {"fixed": fx["aic"], "fitted": free["aic"]}
                if free["aic"] < fx["aic"]:
                    allfits[(f_, "observable", noises[0])] = free
                    free["free_level"] = True
        if len(noises) > 1:
            # noise="auto": the level-dependent noise is fitted for the path and threshold the constant noise chose
            # (one parameter more) and kept if its AIC is lower. From the same start as the constant fit, not from
            # its optimum: a constant-noise optimum at a boundary (a threshold scatter of 0: the dev fold without
            # EMA-0005) left the level fit in a worse local optimum (log-likelihood 6606 against 6647)
            f0, k0, _ = min(allfits, key=lambda k: allfits[k]["aic"])
            base = allfits[(f0, k0, "constant")]
            lev = ml(k0, f0, fix_level=not base.get("free_level"), nz="level")
            lev["free_level"] = base.get("free_level", False)
            # AIC compares regular maxima only: the level fit joins the comparison when its noise parameters'
            # optimum is an interior, locally identified one (_noise_regularity); otherwise the constant noise is
            # kept and the reason recorded (fit_info["noise_rule"])
            # (fresh grids: the windowed quadrature depends on the previous call, noise a Hessian must not see)
            noise_rule = _noise_regularity(lambda xs: lev["nll"](xs, True), lev["r2"].x, lev["names"])
            noise_rule["aic"] = float(lev["aic"])
            if noise_rule["regular"]:
                allfits[(f0, k0, "level")] = lev
                if level_aic is not None:
                    level_aic[(f0, "level")] = level_aic[(f0, "constant")]
        for (f_, k, nz), v in allfits.items():
            if progress:
                print(f"  path {f_}, threshold {k}, noise {nz}: log-likelihood {-v['r2'].fun:.2f}, AIC {v['aic']:.2f}",
                      flush=True)
        fam, kind, nz_best = min(allfits, key=lambda k: allfits[k]["aic"])
        fits = {k: v for (f_, k, nz), v in allfits.items() if f_ == fam and nz == nz_best}
        F = fits[kind]
        gain_aic = None
        if hi_gain != "shared":
            if kind == "latent":
                # per-unit HI gain: nested in the chosen fit (s_g -> 0), started at its optimum
                G = ml(kind, fam, fix_level=not F.get("free_level"), start=F["unpack"](F["r2"].x), nz=nz_best,
                       gain=True)
                gain_aic = {"shared": float(F["aic"]), "unit": float(G["aic"])}
                if hi_gain == "unit" or G["aic"] < F["aic"]:
                    F = G
            else:
                notes.append("per-unit HI gain: latent threshold only; the observable threshold was chosen, so "
                             "the gain is shared")
        unpack, nll, r, r2 = F["unpack"], F["nll"], F["r"], F["r2"]
        th, ins = unpack(r2.x)
        thr_key = "log_sD" if kind == "latent" else "log_sY"
        ngroups = min(nfail, len(units))
        draws, pinfo = [], {"method": "none (point estimate)"}
        if n_draws > 0:
            if ngroups >= 3:
                prior_txt = ("uniform on every standard deviation (s, s_a, sigma, threshold scatter, tau) and on "
                             "rho" + (" and on the noise's level factor kappa" if "log_kappa" in th else "")
                             + (" and on the HI gain's scatter s_g" if "log_sg" in th else "")
                             + "; flat on the rest")

                # the between-unit scales' prior (s, s_a, threshold scatter): uniform on the sd (Gelman 2006), or
                # 1/sd ("log": flat in log sd, the right-Haar prior of a location-scale family, whose posterior
                # predictive interval for a new member of a normal sample is the exact frequentist prediction
                # interval; the uniform one widens it to t with n - 2 dof: 7 units' P5-P95 covers 93 %, not 90 %)
                jb = 0.0 if scale_prior == "log" else 1.0
                prior_txt = (prior_txt.replace("uniform on every standard deviation (s, s_a, sigma, threshold scatter, "
                                               "tau)", "1/sd on the between-unit scales (s, s_a, threshold scatter), "
                                               "uniform on sigma and tau") if jb == 0.0 else prior_txt)

                def log_prior(xs):  # uniform on every standard deviation and on rho, flat on the rest
                    t, i_ = unpack(xs)
                    return (jb * (t["log_s"] + t["log_sa"] + t[thr_key] + t.get("log_sg", 0.0)) + t["log_sigma"]
                            + t.get("log_kappa", 0.0)
                            + sum(v["log_tau"] for v in i_.values())
                            + math.log(max(1.0 - math.tanh(t["atanh_rho"]) ** 2, 1e-300)))
            else:
                # with 2 units / failures the posterior of a between-unit scale under the uniform prior is improper
                # (Gelman 2006: proper from 3 groups on); his recommendation for few groups is a half-Cauchy prior:
                # scale 1 on the log-rate and log-threshold scatters (a factor e between units), the HI's standard
                # deviation over the training records on the offset / observable-threshold scatters (HI units)
                A_thr = 1.0 if kind == "latent" else hi_scale
                prior_txt = (f"{ngroups} failures/units < 3: half-Cauchy on the between-unit scales (s: scale 1, "
                             f"s_a: {hi_scale:.3g}, threshold scatter: {A_thr:.3g}), uniform on sigma, tau and rho"
                             + (" and kappa" if "log_kappa" in th else ""))
                notes.append("between-unit scatter from < 3 failures: proper half-Cauchy prior on its scales")

                def hc(l, A):  # log half-Cauchy(0, A) density of exp(l), in the coordinate l (Jacobian exp(l))
                    return l - math.log1p(math.exp(2 * (l - math.log(A))))

                def log_prior(xs):
                    t, i_ = unpack(xs)
                    return (hc(t["log_s"], 1.0) + hc(t["log_sa"], hi_scale) + hc(t[thr_key], A_thr)
                            + (hc(t["log_sg"], 1.0) if "log_sg" in t else 0.0)
                            + t["log_sigma"] + t.get("log_kappa", 0.0) + sum(v["log_tau"] for v in i_.values())
                            + math.log(max(1.0 - math.tanh(t["atanh_rho"]) ** 2, 1e-300)))

            xd, pinfo = _posterior_draws(lambda xs: nll(xs) - log_prior(xs), r2.x, n_draws,
                                         np.random.default_rng(seed))
            pinfo["prior"] = prior_txt
            draws = [dict(zip(("theta", "inspections"), unpack(x))) for x in xd]
        info = {"n_units": len(units), "n_failures": nfail, "n_censored": len(units) - nfail,
                "threshold": kind, "parameter_uncertainty": pinfo,
                "n_records": int(sum(np.isfinite(u.y).sum() for u in units)), "log_likelihood": float(-r2.fun),
                "n_params": len(F["names"]) + 3 * len(qs), "evals": [int(r.nfev), int(r2.nfev)],
                "lbfgs_loglik": float(-r.fun), "converged": bool(r2.success),
                "start": theta0, "notes": notes, "units": [u.unit for u in units],
                "rate_median": float(np.nanmedian([u.rate() for u in units])),
                "record_spacing": float(np.median([np.median(np.diff(u.t)) for u in units])),
                "hours_per_step": (float(np.median(hp)) if (hp := [u.hours_per_step for u in units
                                                                  if u.hours_per_step]) else None)}
        if fam != "power":
            info["path"] = fam
        if len(fams) > 1:
            info["path_aic"] = {f_: float(min(v["aic"] for (g_, _, _), v in allfits.items() if g_ == f_)) for f_ in fams}
        if len(noises) > 1:  # the noise model's AIC (best path and threshold of each; level: the constant's choice)
            info["noise_aic"] = {"constant": float(min(v["aic"] for (_, _, n_), v in allfits.items()
                                                       if n_ == "constant")), "level": noise_rule["aic"]}
            info["noise_rule"] = noise_rule
        if len(fits) > 1:
            info["threshold_candidates"] = {k: float(-v["r2"].fun) for k, v in fits.items()}
            info["threshold_aic"] = {k: float(v["aic"]) for k, v in fits.items()}
        if kind == "observable" and failure_level is not None and not F.get("free_level"):
            info["failure_level"] = float(failure_level)
        if crossing:
            info["failure_at"] = "crossing"
        if rule is not None:
            info["failure_at_rule"] = rule
        # the prognosis's rate of a unit's future exposure (UnitHistory.rate); a model saved without it (before
        # the mean became the default) keeps the median it was scored with
        info["exposure_rate"] = exposure_rate
        # the future exposure's variability in the prognosis (rul_samples): "renewal" (inverse-Gaussian passage
        # time from the unit's per-step increment variance) or "none" (the single-rate extrapolation; models saved
        # without the key)
        info["exposure_spread"] = exposure_spread
        # the HI noise model: "constant" (one sigma) or "level" (sigma sqrt(1 + kappa^2 L^2), theta["log_kappa"])
        info["noise"] = nz_best
        if hi_gain != "shared":  # the HI gain: shared or per unit (theta["log_sg"]) and the two fits' AIC
            info["hi_gain"] = "unit" if "log_sg" in th else "shared"
            if gain_aic is not None:
                info["gain_aic"] = gain_aic
        if scale_prior != "uniform":
            info["scale_prior"] = scale_prior
        if level_aic is not None:
            info["level_aic"] = level_aic[(fam, nz_best)]
            info["level"] = "fitted" if F.get("free_level") else "fixed"
        return cls(th, E_ref, exposure, feature, ins, info, time_unit, draws=draws)

    def members(self) -> list["LifeModel"]:
        """The models the prognosis mixes: one per posterior parameter draw (threshold law normal in each:
        its scatter's uncertainty is in the draws), or the point estimate alone when there are no draws."""
        if not self.draws:
            return [self]
        return [LifeModel(d["theta"], self.E_ref, self.exposure, self.feature, d.get("inspections", {}),
                          self.fit_info, self.time_unit, plug_in=False) for d in self.draws]

    # ---- prognosis
    def posterior(self, u: UnitHistory, times=None) -> tuple[np.ndarray, np.ndarray]:
        """Grid posteriors over z = ln r, one row per time t_k in ``times`` (default: every record), each
        given the record up to t_k and survival to ``E(t_k)``: (z grid, weights), shapes (K, n)."""
        times = u.t if times is None else np.atleast_1d(np.asarray(times, float))
        hs = [u.truncated(t) for t in times]
        bt = _Batch(hs, self.E_ref, censor_at=list(times), quantities=sorted(self.inspections), path=self.path)
        z, f, _ = bt.grid(self.theta, self.b, self.inspections)
        w = np.exp(f - f.max(1, keepdims=True))
        return z, w / w.sum(1, keepdims=True)

    def threshold_predictive(self) -> tuple[float, float]:
        """(dof, scale) of the predictive distribution of a new unit's ln D: the fitted normal scatter
        estimated from n failures, widened to the Student-t predictive (n - 1 dof, scale s_D sqrt(1 + 1/n))."""
        n = int(self.fit_info.get("n_failures", 0))
        sD = math.exp(self.theta["log_sD" if self.threshold == "latent" else "log_sY"])
        if n >= 3 and self.plug_in:
            return float(n - 1), sD * math.sqrt(1.0 + 1.0 / n)
        return float("inf"), sD

    def sample_failure_exposure(self, z: np.ndarray, E_k: float, rng: np.random.Generator) -> np.ndarray:
        """E_f per sample of z: threshold from its predictive law truncated to 'not failed by E_k'."""
        b = self.b
        df, sc = self.threshold_predictive()
        # the normal / Student-t cdf and inverse from scipy.special (a frozen scipy.stats law per call costs ms)
        cdf, ppf = ((special.ndtr, special.ndtri) if not np.isfinite(df) else
                    (lambda v: special.stdtr(df, v), lambda p: special.stdtrit(df, p)))
        if self.path == "power":
            lo = (z + b * math.log(E_k / self.E_ref)) / sc if E_k > 0 else np.full_like(z, -np.inf)
        else:
            lo = _path_logL(self.path, z, math.log(E_k / self.E_ref), self.theta) / sc if E_k > 0 \
                else np.full_like(z, -np.inf)
        p_lo = cdf(lo)
        u = p_lo + (1.0 - p_lo) * rng.uniform(0.0, 1.0, len(z))
        x = ppf(np.minimum(u, 1 - 1e-15))
        bad = ~np.isfinite(x) | (x < lo)
        x[bad] = lo[bad] + np.abs(rng.standard_normal(int(bad.sum()))) * 0.1  # far tail: just past the bound
        if self.path == "power":
            return self.E_ref * np.exp((sc * x - z) / b)
        # paris: h(u) = D D0 -> u = 1 - (1 + D D0)^(-1/p), E = E_ref u / r
        hD = np.exp(sc * x + self.theta.get("log_D0", 0.0))
        return self.E_ref * -np.expm1(-np.log1p(hD) / b) * np.exp(-z)

    def rul_samples(self, z: np.ndarray, u: UnitHistory, t_k: float, rng: np.random.Generator,
                    h: UnitHistory | None = None) -> np.ndarray:
        """RUL in the unit's time axis for posterior samples ``z`` at time ``t_k`` (alive at ``t_k``);
        ``h``: ``u.truncated(t_k)`` when the caller has it already."""
        h = u.truncated(t_k) if h is None else h
        rate = h.rate(self.fit_info.get("exposure_rate", "median"))
        if not (np.isfinite(rate) and rate > 0):
            rate = float(self.fit_info.get("rate_median", 1.0))
        # the future exposure's own variability (renewal of i.i.d. increments, mean `rate`, variance `v` per time
        # unit); with "renewal+rate" also the sampling uncertainty of the mean rate itself (per sample, normal with
        # variance v / (time of the record's increments)). Models saved without the key: none.
        spread = self.fit_info.get("exposure_spread", "none")
        v = h.rate_var() if spread in ("renewal", "renewal+rate") else 0.0
        rates = _rate_draws(rate, h.rate_mean_var() if spread == "renewal+rate" else 0.0, len(z), rng)
        if self.threshold == "observable":
            return self._rul_observable(z, h, t_k, rate, rng, v=v, rates=rates)
        E_k = h.exposure_at(t_k)
        Ef = self.sample_failure_exposure(z, E_k, rng)
        # the time to accrue D is the first passage of a Brownian motion with that drift and variance, inverse
        # Gaussian (mean D / rate, shape D^2 / v), var = D v / rate^3
        if h.discrete:
            # failure is found at the start of the first step whose start exposure reaches E_f
            E1 = h.exposure_at(t_k + 1, rate)  # exposure at the start of the next step (its own known load)
            return 1.0 + np.ceil(_passage_time(np.maximum(Ef - E1, 0.0), rates, v, rng))
        return _passage_time(Ef - E_k, rates, v, rng)

    def _rul_observable(self, z: np.ndarray, h: UnitHistory, t_k: float, rate: float, rng: np.random.Generator,
                        max_steps: int = 20000, v: float = 0.0, rates=None) -> np.ndarray:
        """Observable threshold: simulate the unit's future HI records from its posterior (z, then the offset a
        from its conditional normal given z and the record, the AR(1) residual carried on from the last record)
        until the HI passes its threshold Y, drawn from its law truncated to 'not passed by any record so far';
        RUL = time of the first record past Y (continuous time: interpolated between the two records; the future
        record spacing is the unit's median spacing). ``v`` > 0: the future exposure is the unit's renewal
        process in its Brownian approximation (drift ``rates`` per sample, or ``rate``; variance ``v`` per time
        unit), the counterpart of the latent threshold's inverse-Gaussian passage time; ``v`` = 0 extrapolates
        at the rate."""
        th, b, c = self.theta, self.b, self.theta["c"]
        n = len(z)
        rho = math.tanh(th.get("atanh_rho", 0.0))
        sig = math.exp(th["log_sigma"])
        kap = math.exp(th["log_kappa"]) if "log_kappa" in th else 0.0  # level-dependent noise (0: constant)
        sg = 1.0 if c >= 0 else -1.0
        ok = np.flatnonzero(np.isfinite(h.y))
        r = np.exp(z)
        if len(ok):
            bt = _Batch([h], self.E_ref, path=self.path)
            ma, va = bt.a_post(r[None, :], th, b)
            a = ma[0] + np.sqrt(va[0]) * rng.standard_normal(n)
            j = ok[-1]
            t_last, yl = float(h.t[j]), float(h.y[j])
            Lj = r * (max(h.E[j], 0.0) / self.E_ref) ** b if self.path == "power" else self.L(z, float(h.E[j]))
            e = yl - a - c * Lj
            if kap:  # level-dependent noise: the AR(1) chain is the standardised residual e / s
                e = e / np.sqrt(_level_var(kap, Lj))
            M = float(np.max(sg * h.y[ok]))
        else:  # no HI yet: offset and residual from their population laws
            a = th["a0"] + math.exp(th["log_sa"]) * rng.standard_normal(n)
            e = sig / math.sqrt(1 - rho * rho) * rng.standard_normal(n)
            t_last, yl, M = float(t_k), float("nan"), -np.inf
        # threshold: normal (or plug-in Student-t) law of sg*Y truncated to > M
        df, sc = self.threshold_predictive()
        cdf, ppf = ((special.ndtr, special.ndtri) if not np.isfinite(df) else
                    (lambda v: special.stdtr(df, v), lambda p: special.stdtrit(df, p)))
        lo = (M - sg * th["Y0"]) / sc
        p_lo = float(cdf(lo)) if np.isfinite(lo) else 0.0
        x = ppf(np.minimum(p_lo + (1.0 - p_lo) * rng.uniform(0.0, 1.0, n), 1 - 1e-15))
        bad = ~np.isfinite(x) | (x < lo)
        x[bad] = lo + np.abs(rng.standard_normal(int(bad.sum()))) * 0.1
        Yo = sg * th["Y0"] + sc * x  # oriented threshold
        dt = 1.0 if h.discrete else (float(np.median(np.diff(h.t))) if len(h.t) >= 2
                                     else float(self.fit_info.get("record_spacing") or rate_scale(self, rate)))
        E_last = h.exposure_at(t_last)

        known_next = h.discrete and h.E_next is not None  # the next step's exposure is known (its own load)
        if rates is not None and np.ndim(rates) == 0:  # one rate: the single-rate extrapolation (+ spread v)
            rate, rates = float(rates), None
        m = np.full(n, rate) if rates is None else np.broadcast_to(np.asarray(rates, float), (n,))
        W = np.zeros(n)  # per sample: the Brownian part of the future exposure accrued so far

        def expo(tt, rows=None, i0=0):
            """Exposure at times tt (the chunk's steps), per sample of ``rows`` when the spread is on."""
            if v <= 0 and rates is None:  # (the arithmetic of the single-rate extrapolation: unchanged)
                if known_next:
                    return h.E_next + (tt - t_last - 1.0) * rate
                return E_last + (tt - t_last) * rate
            dtt = tt - t_last - (1.0 if known_next else 0.0)  # time of unknown increments at each step
            base = (h.E_next if known_next else E_last) + m[rows, None] * dtt[None, :]
            if v <= 0:
                return base
            inc = math.sqrt(v * dt) * rng.standard_normal((len(rows), len(tt)))
            inc[:, (np.arange(len(tt)) + i0) < (1 if known_next else 0)] = 0.0  # the known first step
            Wc = W[rows, None] + np.cumsum(inc, axis=1)
            W[rows] = Wc[:, -1]
            return base + Wc

        T = np.full(n, np.nan)
        alive = np.arange(n)
        y_prev = np.full(n, yl)
        done, chunk = 0, 32
        while len(alive) and done < max_steps:
            k = min(chunk, max_steps - done)
            tt = t_last + dt * np.arange(done + 1, done + k + 1)
            Et = expo(tt, alive, done)
            Et = Et[None, :] if Et.ndim == 1 else Et
            if self.path == "power":
                Lt = r[alive, None] * (np.maximum(Et, 0.0) / self.E_ref) ** b
            else:
                Lt = self.L(z[alive, None], Et)
            mean = a[alive, None] + c * Lt
            xi = sig * rng.standard_normal((len(alive), k))
            ee = np.empty_like(xi)
            ea = e[alive]
            for i in range(k):
                ea = rho * ea + xi[:, i]
                ee[:, i] = ea
            if kap:
                ee *= np.sqrt(_level_var(kap, np.minimum(Lt, 1e150)))
            yy = sg * (mean + ee)
            past = yy >= Yo[alive, None]
            hit = past.any(1)
            first = np.argmax(past, 1)
            rows = alive[hit]
            fi = first[hit]
            if h.discrete:
                T[rows] = tt[fi]
            else:
                y1 = yy[hit, fi]
                y0 = np.where(fi > 0, yy[hit, np.maximum(fi - 1, 0)], sg * y_prev[rows])
                frac = np.where(np.isfinite(y0) & (y1 > y0), (Yo[rows] - y0) / np.where(y1 > y0, y1 - y0, 1.0), 1.0)
                T[rows] = tt[fi] - dt + dt * np.clip(frac, 0.0, 1.0)
            e[alive] = ea
            y_prev[alive] = sg * yy[:, -1]
            alive = alive[~hit]
            done += k
            chunk = min(chunk * 2, 4096)
        T[alive] = t_last + dt * max_steps
        return np.maximum(T - t_k, 0.0 if not h.discrete else 1.0)

    def latent_quantiles(self, z, w, X: float) -> tuple[float, float, float]:
        c = np.cumsum(w)
        q = np.interp([0.05, 0.5, 0.95], c, z)
        return tuple(float(np.exp(v) * X) for v in q)


def _level_var(kappa: float, L):
    """The level-dependent HI noise's variance factor ``s^2 = 1 + kappa^2 L^2`` (record sd ``sigma s``; ``noise=
    "level"``): the one place of that equation outside :meth:`_Batch._hstats`, which computes it in place."""
    return 1.0 + (kappa * L) ** 2


def _rate_draws(rate: float, var: float, n: int, rng: np.random.Generator):
    """The unit's mean exposure rate per sample: ``rate`` itself when ``var`` is 0 (no random draw), else normal
    draws with that sampling variance (kept above 1 % of the estimate: a far tail of the normal approximation)."""
    if var <= 0:
        return rate
    return np.maximum(rate + math.sqrt(var) * rng.standard_normal(n), 0.01 * rate)


def _passage_time(D: np.ndarray, rate, v: float, rng: np.random.Generator) -> np.ndarray:
    """Time for the cumulative exposure to grow by ``D`` (per sample) at mean ``rate`` and variance ``v`` per time
    unit: ``D / rate`` when ``v == 0`` (no random draw), else the inverse-Gaussian first passage of the Brownian
    (normal) approximation of the renewal process of i.i.d. increments, mean ``D / rate``, var ``D v / rate^3``."""
    T = D / rate
    if v <= 0:
        return T
    T = np.array(T, dtype=float)
    pos = D > 0
    if pos.any():
        T[pos] = rng.wald(T[pos], D[pos] ** 2 / v)
    return T


def rate_scale(model: "LifeModel", rate: float) -> float:
    """Record spacing for a model file without ``record_spacing``: 1/20 of the reference exposure in time."""
    return max(model.E_ref / max(rate, 1e-300) / 20.0, 1e-12)


def _split(n: int, k: int) -> list[int]:
    """n samples over k members, as evenly as possible."""
    return [n // k + (1 if i < n % k else 0) for i in range(k)]


def _latent_quantiles(parts, qs=(0.05, 0.5, 0.95)) -> tuple[float, ...]:
    """Quantiles of the latent degradation L = exp(z) X pooled over members: ``parts`` = [(z grid, weights,
    X)], equal member weights; the mixture CDF on the union of the members' ln L grids (exact on a grid:
    one member gives :meth:`LifeModel.latent_quantiles`)."""
    if any(X <= 0 for _, _, X in parts):
        return tuple(0.0 for _ in qs)
    grids = [(z + math.log(X), np.cumsum(w)) for z, w, X in parts]
    if len(grids) == 1:
        g, c = grids[0]
    else:
        g = np.unique(np.concatenate([v for v, _ in grids]))
        c = np.mean([np.interp(g, v, cw, left=0.0, right=1.0) for v, cw in grids], axis=0)
    return tuple(float(np.exp(v)) for v in np.interp(qs, c, g))


def predict_history(model: LifeModel, u: UnitHistory, *, n_samples: int = 2000, seed: int = 0,
                    t_start: float | None = None, method: str = "grid"):
    """RUL history of one unit: posterior at every record from ``t_start`` on (``method``: ``grid`` = exact
    posterior over z; ``ukf`` = unscented Kalman filter over (z, a) on the same model). With posterior
    parameter draws (:meth:`LifeModel.members`) every draw gets its own posterior / filter and the samples
    are pooled (posterior predictive over the population parameters)."""
    from hd_prognostic.tracking import RULHistory

    rng = np.random.default_rng(seed)
    hist = RULHistory(unit=u.unit, time_unit=model.time_unit, state_names=("L",), threshold=1.0)
    members = model.members()
    ns = _split(n_samples, len(members))
    if method == "ukf":
        ukfs = [_UKF(m) for m in members]
    else:
        post = [m.posterior(u) for m in members]
    hrs, h5, h50, h95 = u.hours_per_step or model.fit_info.get("hours_per_step"), [], [], []
    for k, tk in enumerate(u.t):
        rs, lat, parts = [], [], []
        hk = u.truncated(tk)
        for j, m in enumerate(members):
            if not ns[j]:
                continue
            X = (max(u.E[k], 0.0) / m.E_ref) ** m.b
            pw = m.path == "power"
            if method == "ukf":
                f = ukfs[j]
                for ti, q, v in u.events.inspections:  # the unit's inspections since the previous record
                    if q in m.inspections and ti <= tk and (k == 0 or ti > u.t[k - 1]):
                        f.inspect(v, m.inspections[q], u.exposure_at(ti))
                f.update(u.y[k], X, u.E[k])
                z = f.sample(ns[j], rng)
                X *= m.latent_scale()
                if m.threshold == "observable":  # survival so far does not depend on z there
                    lat.append(np.exp(z) * X if pw else m.L(z, u.E[k]) * m.latent_scale())
                    if t_start is None or tk >= t_start:
                        rs.append(m.rul_samples(z, u, tk, rng, hk))
                    continue
                # survival to E(t_k) as importance weights on the Gaussian posterior
                sD = math.exp(m.theta["log_sD"])
                lw = special.log_ndtr(-(z + m.b * math.log(max(u.E[k], 1e-300) / m.E_ref) if pw
                                        else np.log(m.L(z, u.E[k]))) / sD) \
                    if u.E[k] > 0 else np.zeros(ns[j])
                w = np.exp(lw - lw.max())
                z = z[rng.choice(ns[j], ns[j], p=w / w.sum())]
            else:
                zg, wg = post[j][0][k], post[j][1][k]
                z = rng.choice(zg, ns[j], p=wg) + rng.uniform(-0.5, 0.5, ns[j]) * (zg[1] - zg[0])
                X *= m.latent_scale()
                if pw or u.E[k] <= 0:
                    parts.append((zg, wg, X if pw else 0.0))
                else:  # ln L is increasing in z: its quantiles are the transformed grid's
                    parts.append((np.log(m.L(zg, u.E[k])), wg, m.latent_scale()))
            lat.append(np.exp(z) * X if pw else m.L(z, u.E[k]) * m.latent_scale())
            if t_start is None or tk >= t_start:
                rs.append(m.rul_samples(z, u, tk, rng, hk))
        lq = _latent_quantiles(parts) if parts else np.quantile(np.concatenate(lat), [0.05, 0.5, 0.95])
        hist.t.append(float(tk))
        hist.z.append(float(u.y[k]))
        hist.state_mean.append([float(lq[1])])
        hist.state_p5.append([float(lq[0])])
        hist.state_p95.append([float(lq[2])])
        hist.ess.append(float("nan"))
        if t_start is not None and tk < t_start:
            continue
        r = np.concatenate(rs)
        q = np.quantile(r, [0.05, 0.5, 0.95])
        hist.rul_t.append(float(tk))
        hist.p5.append(float(q[0]))
        hist.p50.append(float(q[1]))
        hist.p95.append(float(q[2]))
        hist.mean.append(float(np.mean(r)))
        hist.samples.append(r)
        if hrs:
            h5.append(float(q[0] * hrs))
            h50.append(float(q[1] * hrs))
            h95.append(float(q[2] * hrs))
    hist.meta.update({"model": "life model (latent degradation path)", "method": method,
                      "parameter_draws": len(model.draws),
                      "exposure": model.exposure, "feature": model.feature, "hours_per_step": hrs})
    if hrs:
        hist.meta["rul_hours"] = {"p5": h5, "p50": h50, "p95": h95}
    return hist


class _UKF:
    """Unscented Kalman filter over (z, a) of one unit (static state; y = a + c exp(z) X + e); with a per-unit HI
    gain (``log_sg`` in the model) over (z, a, g), y = a + c (1 + g) exp(z) X + e."""

    def __init__(self, model: LifeModel):
        th = model.theta
        self.model = model
        self.c, self.sig = th["c"], math.exp(th["log_sigma"])
        self.kap = math.exp(th["log_kappa"]) if "log_kappa" in th else 0.0  # level-dependent noise
        self.rho = math.tanh(th.get("atanh_rho", 0.0))
        self.prev = None  # (y, X) of the previous finite record: AR(1) residuals are prewhitened
        sd = [math.exp(th["log_s"]), math.exp(th["log_sa"])] + ([math.exp(th["log_sg"])] if "log_sg" in th else [])
        self.x = np.array([th["mu"], th["a0"], 0.0][:len(sd)])
        self.P = np.diag(np.square(sd))
        self.cc, self.wm, self.wc = merwe_weights(len(sd))  # state (z, a[, g]); alpha 0.5, beta 2, kappa 0

    def _lat(self, z: np.ndarray, X: float, E) -> np.ndarray:
        """Latent path at the sigma points: exp(z) X (power law; X = (E/E_ref)^b) or the model's path at E."""
        if self.model.path == "power" or E is None:
            return np.exp(z) * X
        return self.model.L(z, E)

    def _sigma_points(self) -> np.ndarray:
        """The 2n + 1 sigma points (rows) of the state (z, a) about its mean (merwe_weights' scaling)."""
        P = 0.5 * (self.P + self.P.T)
        w, V = np.linalg.eigh(self.cc * P)
        S = V @ np.diag(np.sqrt(np.maximum(w, 0.0)))
        return np.vstack([self.x, self.x + S.T, self.x - S.T])

    def _correct(self, Xs: np.ndarray, Z: np.ndarray, r2: float, meas: float) -> None:
        """The unscented measurement update: sigma points ``Xs`` predicted as ``Z``, measurement variance ``r2``."""
        zm = self.wm @ Z
        Sz = self.wc @ (Z - zm) ** 2 + r2
        C = (self.wc[:, None] * (Xs - self.x)).T @ (Z - zm)
        K = C / Sz
        self.x = self.x + K * (meas - zm)
        self.P = self.P - np.outer(K, K) * Sz

    def update(self, y: float, X: float, E: float | None = None) -> None:
        if not np.isfinite(y):
            self.prev = None
            return
        Xs = self._sigma_points()
        rho = self.rho
        pw = self.model.path == "power" or E is None
        kap = self.kap
        cg = self.c * (1.0 + Xs[:, 2]) if Xs.shape[1] > 2 else self.c  # the unit's HI gain at the sigma points
        if kap:  # level-dependent noise: records scaled by s = sqrt(1 + kappa^2 L^2) at the current mean of z
            sc = lambda X_, E_: 1.0 / math.sqrt(_level_var(kap, float(self._lat(np.array([self.x[0]]), X_, E_)[0])))  # noqa: E731
        if self.prev is None:  # chain start: marginal variance sigma^2 / (1 - rho^2)
            Z = Xs[:, 1] + (cg * np.exp(Xs[:, 0]) * X if pw else cg * self._lat(Xs[:, 0], X, E))
            r2, meas = self.sig ** 2 / (1.0 - rho * rho), y
            if kap:
                w = sc(X, E)
                Z, meas = Z * w, meas * w
        elif kap:
            yp, Xp, Ep = self.prev
            w, wp = sc(X, E), sc(Xp, Ep)
            Z = Xs[:, 1] * (w - rho * wp) + cg * (self._lat(Xs[:, 0], X, E) * w
                                                 - rho * wp * self._lat(Xs[:, 0], Xp, Ep))
            r2, meas = self.sig ** 2, y * w - rho * yp * wp
        else:
            yp, Xp, Ep = self.prev
            Z = Xs[:, 1] * (1.0 - rho) + (cg * np.exp(Xs[:, 0]) * (X - rho * Xp) if pw else
                                          cg * (self._lat(Xs[:, 0], X, E) - rho * self._lat(Xs[:, 0], Xp, Ep)))
            r2, meas = self.sig ** 2, y - rho * yp
        self.prev = (y, X, E)
        self._correct(Xs, Z, r2, meas)

    def inspect(self, v: float, qmap: dict, E: float) -> None:
        """Unscented update with one inspection ``v = alpha + beta L(z, E) + N(0, tau^2)`` at exposure ``E`` (the
        grid posterior's inspection term, :meth:`_Batch.logf`); the HI's AR(1) chain is not touched."""
        if not (np.isfinite(v) and E > 0):
            return
        Xs = self._sigma_points()
        Z = qmap["alpha"] + qmap["beta"] * np.asarray(self.model.L(Xs[:, 0], E), float)
        self._correct(Xs, Z, math.exp(2.0 * qmap["log_tau"]), v)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        sd = math.sqrt(max(self.P[0, 0], 0.0))
        return self.x[0] + sd * rng.standard_normal(n)


def fit_best(candidates: dict[str, list[UnitHistory]], feature: str = "hi", time_unit: str = "mission",
             progress: bool = False, n_draws: int = 20, threshold: str = "auto",
             failure_level: float | None = None, path: str = "power", failure_at: str = "interval",
             noise: str = "constant", exposure_spread: str = "renewal", hi_gain: str = "shared") -> LifeModel:
    """Fit one model per exposure candidate (same HI data and events) and keep the maximum likelihood one
    (its posterior parameter draws are then computed, ``n_draws``); the log-likelihoods of all candidates go
    into ``fit_info["exposure_candidates"]``."""
    fits, errs = {}, {}
    for name, units in candidates.items():
        try:
            fits[name] = LifeModel.fit(units, exposure=name, feature=feature, time_unit=time_unit, n_draws=0,
                                       threshold=threshold, failure_level=failure_level, path=path,
                                       failure_at=failure_at, noise=noise, exposure_spread=exposure_spread,
                                       hi_gain=hi_gain)
        except ValueError as e:
            errs[name] = str(e)
            continue
        if progress:
            print(f"  exposure {name}: log-likelihood {fits[name].fit_info['log_likelihood']:.2f}", flush=True)
    if not fits:
        raise ValueError("; ".join(f"{k}: {v}" for k, v in errs.items()))
    best = max(fits, key=lambda k: fits[k].fit_info["log_likelihood"])
    m = fits[best]
    if n_draws > 0:  # same data and start: the same maximum, now with the parameter posterior
        m = LifeModel.fit(candidates[best], exposure=best, feature=feature, time_unit=time_unit, n_draws=n_draws,
                          threshold=m.threshold, failure_level=failure_level, path=m.path, failure_at=failure_at,
                          noise=m.fit_info.get("noise", "constant"), exposure_spread=exposure_spread,
                          hi_gain=m.fit_info.get("hi_gain", "shared"))
        m.fit_info["threshold_candidates"] = fits[best].fit_info.get("threshold_candidates")
        for k in ("noise_aic", "noise_rule", "gain_aic"):
            if k in fits[best].fit_info:
                m.fit_info[k] = fits[best].fit_info[k]
        if "path_aic" in fits[best].fit_info:
            m.fit_info["path_aic"] = fits[best].fit_info["path_aic"]
    m.fit_info["exposure_candidates"] = {k: f.fit_info["log_likelihood"] for k, f in fits.items()}
    if errs:
        m.fit_info["exposure_errors"] = errs
    return m


def predict_at(model: LifeModel, u: UnitHistory, rng: np.random.Generator, n_samples: int = 500) -> dict:
    """One prediction at the unit's last record (what the prognostic node publishes per mission):
    latent degradation P5/P50/P95 (1 = median failure threshold) and RUL samples in the unit's time axis,
    pooled over the model's posterior parameter draws."""
    tk = float(u.t[-1])
    members = model.members()
    parts, rs = [], []
    for m, n in zip(members, _split(n_samples, len(members))):
        if not n:
            continue
        zg, wg = m.posterior(u, [tk])
        zg, wg = zg[0], wg[0]
        z = rng.choice(zg, n, p=wg) + rng.uniform(-0.5, 0.5, n) * (zg[1] - zg[0])
        if m.path == "power" or u.E[-1] <= 0:
            X = (max(u.E[-1], 0.0) / m.E_ref) ** m.b * m.latent_scale() if m.path == "power" else 0.0
            parts.append((zg, wg, X))
        else:
            parts.append((np.log(m.L(zg, u.E[-1])), wg, m.latent_scale()))
        rs.append(m.rul_samples(z, u, tk, rng))
    return {"latent": _latent_quantiles(parts), "rul": np.concatenate(rs)}
