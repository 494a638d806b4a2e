"""Additive model terms: the one format shared by the twin physics and discovery.

A *term* is a JSON-serialisable dict that adds a linear combination of basis
functions to the model of one measured signal (``tau_m`` or ``Q_red``)::

    {
      "name": "position_periodic_friction",   # canonical PHYSICS.md section 7 name, or "unknown"
      "signal": "tau_m",                      # the measured signal whose model it adds to
      "variable": "theta_m",                  # what it depends on
      "order": 2,                             # cycles per revolution of ``variable`` or None
      "form": "F_2 sin(2 theta_m + rho_2) sgn(omega_m)",   # human-readable formula
      "basis": [ {basis spec}, ... ],         # composable basis functions (below)
      "coef": [c_0, c_1, ...],                # one coefficient per basis function, SI units
      "parameters": {"F_2": 0.03, "rho_2": 1.1}  # the same term in physically named parameters
    }

The term's value is ``sum_i coef[i] * basis_i(signals)`` in N*m (the unit of
its ``signal``).  ``evaluate_terms(terms, signals, xp=numpy)`` evaluates a list
of terms on numpy arrays or, with ``xp=torch``, on torch tensors (so the PINN's
physics residual can carry the same terms, differentiably).

Basis specs (``signals`` keys: theta_m, theta_f, omega_m, omega_f, tau_m,
Q_red, temperature, i_q, alpha_m, alpha_f, phi, windup (= -phi, derived from phi
when absent), ...; angles rad, speeds rad/s,
torques N*m, temperature degC, currents A):

================================================  =============================================
spec                                              value
================================================  =============================================
``{"op": "const"}``                               1
``{"op": "var", "var": v}``                       v
``{"op": "sin", "var": v, "k": k}``               sin(k v)           (k may be fractional)
``{"op": "cos", "var": v, "k": k}``               cos(k v)
``{"op": "sin", "var": v, "k": k,                 sin(k (v + s r)): the angle re-timed by the acquisition skew s
   "skew_s": s, "rate": r}``                      [s] with its rate r (first order; cos alike, see :func:`retimed_angle`)
``{"op": "sgn", "var": v, "eps": e}``             sgn(v); tanh(v / e) when e > 0 (smooth, differentiable)
``{"op": "abs", "var": v}``                       abs(v)
``{"op": "pow", "var": v, "p": p}``               v ** p (odd-symmetric sign(v) abs(v)**p if ``"odd": true``)
``{"op": "pow", "var": v, "p": p, "ref": r,       (v - r) ** p on [lo, hi], continued linearly beyond (its value and
   "lo": a, "hi": b}``                            slope at the bound: a function known on the range of the data it
                                                  was identified on, see :func:`pow_within`)
``{"op": "offset", "var": v, "ref": r}``          v - r              (e.g. temperature - T_ref)
``{"op": "expm1", "var": v, "k": k, "ref": r}``   exp(k (v - r)) - 1 (e.g. Reynolds' viscosity law in temperature)
``{"op": "stribeck", "var": v, "v_s": s,          exp(-(abs(v)/s)**delta) * sgn(v)
   "delta": d, "eps": e}``
``{"op": "exp_decay", "var": v, "v_s": s,         exp(-(abs(v)/s)**delta)
   "delta": d}``
``{"op": "deadzone", "var": v, "width": d}``      sgn(v) max(abs(v) - d, 0)   (lost motion of half-width d)
``{"op": "deadzone", "var": v, "width": d,        s [softplus((v - d)/s) - softplus((-v - d)/s)]: the same lost
   "edge": s}``                                   motion with softplus corners of width s (teeth that engage over
                                                  a twist s, a compliant first contact); s -> 0 gives the hard one
``{"op": "within", "var": v, "width": d}``        1 where abs(v) < d, 0 where abs(v) > d (1/2 at d): inside that lost
                                                  motion, no contact (1 - the dead zone's slope)
``{"op": "lowpass", "var": v, "k": k,              1 / (1 + (k v / c)^2): the share of a disturbance at the frequency
   "corner": c}``                                 k |v| [rad/s] that a band-limited loop shows, corner c (e.g. a
                                                  ripple of order k in theta_m at speed v = omega_m in the logged
                                                  current: beyond the speed loop's band the rotor's inertia takes it)
``{"op": "prod", "factors": [spec, ...]}``        product of the factors
``{"op": "sum", "terms": [spec, ...],              sum_i w_i spec_i: a fixed function made of others (e.g. an
   "weights": [w, ...]}``                         identified torsion law inside a product, its weights fixed)
================================================  =============================================

Everything here is pure and array-namespace agnostic: ``xp`` must provide
``sin, cos, tanh, sign, abs, exp, log1p, ones_like``; both ``numpy`` and ``torch`` do.
"""

from __future__ import annotations

import copy
import json
import math
from typing import Any, Iterable, Mapping

import numpy as np

#: Canonical effect names (PHYSICS.md section 7). ``"unknown"`` is also valid
#: for a term that fits none of them (reported with variable/order/form).
CATALOG_NAMES = (
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "temperature_dependent_friction",
    "load_dependent_friction",
    "position_periodic_friction",
    "position_periodic_torque",
    "kinematic_error_harmonic",
    "position_dependent_stiffness",
    "nonlinear_stiffness",
    "hysteresis",
    "backlash",
    "cogging_torque",
    "current_ripple",
    "motor_thermal_drift",
)
TARGET_SIGNALS = ("tau_m", "Q_red")
BASIS_OPS = ("const", "var", "sin", "cos", "sgn", "abs", "pow", "offset", "stribeck", "exp_decay", "deadzone", "within",
             "expm1", "lowpass", "prod", "sum")

# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------


def _finite_number(x: Any, what: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number, got {x!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{what}: must be finite, got {v!r}")
    return v


#: how deep products and sums may nest (discovery's deepest is 3: a harmonic times a sum of products); a model file
#: nested deeper is refused by name, not by Python's recursion limit
MAX_BASIS_DEPTH = 16


def validate_basis(spec: Mapping[str, Any], where: str = "basis", _depth: int = 0) -> None:
    """Raise ``ValueError`` naming ``where`` and the problem if ``spec`` is malformed."""
    if not isinstance(spec, Mapping):
        raise ValueError(f"{where}: a basis spec must be a dict, got {type(spec).__name__}")
    if _depth > MAX_BASIS_DEPTH:
        raise ValueError(f"{where}: products and sums nested deeper than {MAX_BASIS_DEPTH} levels")
    op = spec.get("op")
    if op not in BASIS_OPS:
        raise ValueError(f"{where}: unknown basis op {op!r}; one of {BASIS_OPS}")
    if op == "const":
        return
    if op == "prod":
        factors = spec.get("factors")
        if not isinstance(factors, list) or not factors:
            raise ValueError(f"{where}: 'prod' needs a non-empty list 'factors'")
        for i, f in enumerate(factors):
            validate_basis(f, f"{where}.factors[{i}]", _depth + 1)
        return
    if op == "sum":
        parts, weights = spec.get("terms"), spec.get("weights")
        if not isinstance(parts, list) or not parts:
            raise ValueError(f"{where}: 'sum' needs a non-empty list 'terms'")
        if not isinstance(weights, list) or len(weights) != len(parts):
            n = len(weights) if isinstance(weights, list) else None
            raise ValueError(f"{where}: 'sum' needs one number in 'weights' per spec in 'terms' ({len(parts)}), got {n}")
        for i, (f, w) in enumerate(zip(parts, weights)):
            _finite_number(w, f"{where}.weights[{i}]")
            validate_basis(f, f"{where}.terms[{i}]", _depth + 1)
        return
    if not isinstance(spec.get("var"), str) or not spec["var"]:
        raise ValueError(f"{where}: op {op!r} needs a signal name in 'var'")
    if op in ("sin", "cos"):
        _finite_number(spec.get("k"), f"{where}: 'k' of {op}")
        if "skew_s" in spec or "rate" in spec:
            _finite_number(spec.get("skew_s"), f"{where}: 'skew_s' of {op}")
            if not isinstance(spec.get("rate"), str) or not spec["rate"]:
                raise ValueError(f"{where}: {op} with 'skew_s' needs the angle's rate signal in 'rate'")
    elif op == "pow":
        _finite_number(spec.get("p"), f"{where}: 'p' of pow")
        if "lo" in spec or "hi" in spec:
            lo = _finite_number(spec.get("lo"), f"{where}: 'lo' of pow")
            hi = _finite_number(spec.get("hi"), f"{where}: 'hi' of pow")
            _finite_number(spec.get("ref", 0.0), f"{where}: 'ref' of pow")
            if not lo < hi:
                raise ValueError(f"{where}: pow with a range needs lo < hi, got lo={lo}, hi={hi}")
            if spec.get("odd"):
                raise ValueError(f"{where}: pow with a range is not odd-symmetric ('odd' and 'lo'/'hi' together)")
    elif op == "offset":
        _finite_number(spec.get("ref", 0.0), f"{where}: 'ref' of offset")
    elif op == "expm1":
        _finite_number(spec.get("k"), f"{where}: 'k' of expm1")
        _finite_number(spec.get("ref", 0.0), f"{where}: 'ref' of expm1")
    elif op in ("deadzone", "within"):
        if _finite_number(spec.get("width"), f"{where}: 'width' of {op}") < 0:
            raise ValueError(f"{where}: {op} needs width >= 0, got {spec.get('width')}")
        if op == "deadzone" and "edge" in spec and _finite_number(spec.get("edge"), f"{where}: 'edge' of deadzone") < 0:
            raise ValueError(f"{where}: deadzone needs edge >= 0, got {spec.get('edge')}")
    elif op == "lowpass":
        _finite_number(spec.get("k"), f"{where}: 'k' of lowpass")
        if _finite_number(spec.get("corner"), f"{where}: 'corner' of lowpass") <= 0:
            raise ValueError(f"{where}: lowpass needs corner > 0, got {spec.get('corner')}")
    elif op in ("stribeck", "exp_decay"):
        s = _finite_number(spec.get("v_s"), f"{where}: 'v_s' of {op}")
        d = _finite_number(spec.get("delta", 1.0), f"{where}: 'delta' of {op}")
        if s <= 0 or d <= 0:
            raise ValueError(f"{where}: {op} needs v_s > 0 and delta > 0, got v_s={s}, delta={d}")
    if op in ("sgn", "stribeck"):
        e = _finite_number(spec.get("eps", 0.0), f"{where}: 'eps' of {op}")
        if e < 0:
            raise ValueError(f"{where}: 'eps' must be >= 0, got {e}")


def validate_term(term: Mapping[str, Any], where: str = "term") -> None:
    """Raise ``ValueError`` naming the term and the problem if it is malformed."""
    if not isinstance(term, Mapping):
        raise ValueError(f"{where}: a term must be a dict, got {type(term).__name__}")
    name = term.get("name")
    where = f"{where} {name!r}"
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}: 'name' must be a non-empty string")
    if term.get("signal") not in TARGET_SIGNALS:
        raise ValueError(f"{where}: 'signal' must be one of {TARGET_SIGNALS}, got {term.get('signal')!r}")
    basis = term.get("basis")
    if not isinstance(basis, list) or not basis:
        raise ValueError(f"{where}: 'basis' must be a non-empty list of basis specs")
    for i, b in enumerate(basis):
        validate_basis(b, f"{where}.basis[{i}]")
    coef = term.get("coef")
    if coef is None or len(coef) != len(basis):
        n = None if coef is None else len(coef)
        raise ValueError(f"{where}: 'coef' needs {len(basis)} numbers (one per basis function), got {n}")
    if not _is_tensor(coef):
        for i, c in enumerate(coef):
            _finite_number(c, f"{where}.coef[{i}]")
    order = term.get("order")
    if order is not None:
        _finite_number(order, f"{where}: 'order'")


def children(spec: Mapping[str, Any]) -> list:
    """The specs a composite basis spec is made of (a product's factors, a sum's terms); [] for a leaf."""
    op = spec.get("op")
    return list(spec["factors"]) if op == "prod" else list(spec["terms"]) if op == "sum" else []


def with_children(spec: Mapping[str, Any], parts: list) -> dict:
    """A copy of the composite ``spec`` with its parts replaced by ``parts`` (same order)."""
    return {**spec, ("factors" if spec.get("op") == "prod" else "terms"): list(parts)}


def _is_tensor(x: Any) -> bool:
    return type(x).__module__.startswith("torch")


# ---------------------------------------------------------------------------
# evaluation
# ---------------------------------------------------------------------------


#: Signals derivable from others when a caller does not supply them: name -> (source, factor).
#: ``windup`` = theta_m/N - theta_f = -phi (input leading; the transmitted torque is +K windup).
DERIVED_SIGNALS = {"windup": ("phi", -1.0), "windup_dot": ("phi_dot", -1.0)}


def _get(signals: Mapping[str, Any], var: str, where: str):
    try:
        return signals[var]
    except KeyError:
        if var in DERIVED_SIGNALS and DERIVED_SIGNALS[var][0] in signals:
            src, f = DERIVED_SIGNALS[var]
            return f * signals[src]
        raise KeyError(
            f"{where}: signal {var!r} is needed but not available; have {sorted(signals)}"
        ) from None


def _ref_signal(signals: Mapping[str, Any]):
    for v in signals.values():
        if hasattr(v, "shape") and len(getattr(v, "shape", ())) >= 1:
            return v
    raise ValueError("evaluate: no array signal to take the sample shape from")


def evaluate_basis(spec: Mapping[str, Any], signals: Mapping[str, Any], xp=np, where: str = "basis"):
    """Value of one basis function on ``signals`` (arrays of one shape), same namespace as ``xp``."""
    op = spec["op"]
    if op == "const":
        return xp.ones_like(_ref_signal(signals))
    if op == "prod":
        out = None
        for i, f in enumerate(spec["factors"]):
            v = evaluate_basis(f, signals, xp, f"{where}.factors[{i}]")
            out = v if out is None else out * v
        return out
    if op == "sum":
        out = None
        for i, (f, w) in enumerate(zip(spec["terms"], spec["weights"])):
            v = float(w) * evaluate_basis(f, signals, xp, f"{where}.terms[{i}]")
            out = v if out is None else out + v
        return out
    x = _get(signals, spec["var"], where)
    if op == "var":
        return x * 1.0
    if op in ("sin", "cos") and "skew_s" in spec:
        x = retimed_angle(x, _get(signals, spec["rate"], where), float(spec["skew_s"]))
    if op == "sin":
        return xp.sin(float(spec["k"]) * x)
    if op == "cos":
        return xp.cos(float(spec["k"]) * x)
    if op == "sgn":
        return _sgn(x, float(spec.get("eps", 0.0)), xp)
    if op == "abs":
        return xp.abs(x)
    if op == "pow":
        p = float(spec["p"])
        if "lo" in spec:
            v = pow_within(x, p, float(spec.get("ref", 0.0)), float(spec["lo"]), float(spec["hi"]))
        elif spec.get("odd"):
            v = xp.sign(x) * xp.abs(x) ** p
        else:
            v = x**p
        return _finite_where_input_is(v, x, xp, where, f"pow with p={p:g}")
    if op == "offset":
        return x - float(spec.get("ref", 0.0))
    if op == "expm1":
        k, ref = float(spec["k"]), float(spec.get("ref", 0.0))
        return _finite_where_input_is(xp.exp(k * (x - ref)) - 1.0, x, xp, where, f"expm1 with k={k:g}, ref={ref:g}")
    if op == "deadzone":
        d, e = float(spec["width"]), float(spec.get("edge", 0.0))
        if e > 0.0:
            return e * (_softplus((x - d) / e, xp) - _softplus((-x - d) / e, xp))
        a = xp.abs(x) - d
        return xp.sign(x) * (a + xp.abs(a)) / 2
    if op == "within":
        return (1.0 - xp.sign(xp.abs(x) - float(spec["width"]))) / 2
    if op == "lowpass":
        z = float(spec["k"]) * x / float(spec["corner"])
        return 1.0 / (1.0 + z * z)
    if op in ("stribeck", "exp_decay"):
        s, d = float(spec["v_s"]), float(spec.get("delta", 1.0))
        decay = xp.exp(-((xp.abs(x) / s) ** d))
        if op == "exp_decay":
            return decay
        return decay * _sgn(x, float(spec.get("eps", 0.0)), xp)
    raise ValueError(f"{where}: unknown basis op {op!r}")  # pragma: no cover (validated)


def _softplus(z, xp):
    """log(1 + exp(z)) without overflow: max(z, 0) + log1p(exp(-|z|))."""
    return (z + xp.abs(z)) / 2 + xp.log1p(xp.exp(-xp.abs(z)))


def _finite_where_input_is(v, x, xp, where: str, what: str):
    """``v`` unchanged, or ``ValueError`` naming the basis where it is not finite on a finite input.

    The two ops whose value can leave the reals from finite parameters and finite signals: ``expm1`` overflows
    where k (v - ref) exceeds ~709 (a hostile or mis-scaled k in a model file), and ``pow`` gives NaN on a
    negative base with a fractional exponent and inf at 0 with a negative one. Their value would otherwise
    reach a residual, a fault flag or a training loss as inf/NaN, silently. A non-finite input (a dropout)
    stays the caller's: only samples where ``x`` is finite are checked."""
    bad = xp.isfinite(x) & ~xp.isfinite(v)
    if bool(bad.any()):
        flat, xs = bad.reshape(-1), x.reshape(-1)
        idx = int(np.flatnonzero(flat)[0]) if xp is np else int(flat.nonzero()[0, 0])
        total = flat.size if xp is np else flat.numel()
        raise ValueError(f"{where}: {what} is not finite on {int(flat.sum())} of {total} samples with finite "
                         f"input (first at input {float(xs[idx]):.6g}); the term's parameters do not fit the "
                         "signal's range")
    return v


def retimed_angle(theta, rate, skew_s: float):
    """The equation of the acquisition skew: a logged angle at the instant its torque sample stands for,
    ``theta(t + s) ~ theta + s theta'`` [rad], with ``rate`` the angle's logged speed [rad/s] and ``s`` [s] the
    skew of the torque sample after the angle's (a logger that latches the encoder at the start of its period
    and averages the current over it: s ~ half the period; ``hd_ground.discovery`` identifies s from the
    speeds' lag and keeps it only where the fit bags' CV prefers it). First order, per sample and causal (the
    twin evaluates it on each incoming sample as discovery does on the log); its error s^2 theta'' / 2 is
    below 0.01 rad of the angle for s = 2.4 ms up to theta'' = 3000 rad/s^2."""
    return theta + skew_s * rate


def pow_within(x, p: float, ref: float, lo: float, hi: float):
    """(x - ref)^p on [lo, hi], continued linearly beyond: b^p + p b^(p-1) (x - b) with b the bound (u = x - ref).

    A smooth function identified as a polynomial over the range of its data (discovery's stand-in for a position
    effect seen over too short a stroke to show its periodicity) is known there only; its cubic term, free over the
    range, grows as u^3 beyond it. The continuation is the natural cubic spline's boundary condition (zero curvature
    beyond the outer knots; Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, 5.2.1: polynomial
    fits are erratic near the boundaries and extrapolation is dangerous): the least-curved function through the
    fitted values and slopes at the bounds. Linear in the coefficients (each power continued alike), per sample,
    and written with abs only (numpy and torch alike)."""
    b = (x + lo + abs(x - lo)) / 2  # max(x, lo)
    b = (b + hi - abs(b - hi)) / 2  # min(., hi)
    ub = b - ref
    if p == 0:
        return x * 0.0 + 1.0
    return ub**p + p * ub ** (p - 1) * (x - b)


def _sgn(x, eps: float, xp):
    return xp.tanh(x / eps) if eps > 0 else xp.sign(x)


def basis_matrix(basis: Iterable[Mapping[str, Any]], signals: Mapping[str, Any], xp=np):
    """Columns of the basis functions, shape (n_samples, n_basis) (numpy or torch)."""
    cols = [evaluate_basis(b, signals, xp, f"basis[{i}]") for i, b in enumerate(basis)]
    return xp.stack(cols, -1)


def evaluate_term(term: Mapping[str, Any], signals: Mapping[str, Any], xp=np):
    """Value of one term, N*m: ``sum_i coef[i] * basis_i(signals)``."""
    out = None
    name = term.get("name", "?")
    for i, (b, c) in enumerate(zip(term["basis"], term["coef"])):
        v = evaluate_basis(b, signals, xp, f"term {name!r}.basis[{i}]")
        v = v * (c if _is_tensor(c) else float(c))
        out = v if out is None else out + v
    return out


def evaluate_terms(terms: list[Mapping[str, Any]], signals: Mapping[str, Any], xp=np, *, signal: str | None = None):
    """Sum of ``terms`` on ``signals`` (numpy arrays with ``xp=numpy``, tensors with ``xp=torch``).

    ``signal`` restricts the sum to the terms that add to that measured signal
    (``"tau_m"`` or ``"Q_red"``); ``None`` sums them all. With no (matching)
    term the result is zeros of the signals' sample shape. Raises ``ValueError``
    on a malformed term and ``KeyError`` naming the term and the missing signal.
    """
    out = None
    for j, t in enumerate(terms):
        validate_term(t, f"terms[{j}]")
        if signal is not None and t["signal"] != signal:
            continue
        v = evaluate_term(t, signals, xp)
        out = v if out is None else out + v
    if out is None:
        out = xp.zeros_like(_ref_signal(signals))
    return out


def required_signals(terms: Iterable[Mapping[str, Any]]) -> set[str]:
    """Names of the signals a list of terms reads."""
    need: set[str] = set()

    def walk(b):
        if b["op"] in ("prod", "sum"):
            for f in b["factors" if b["op"] == "prod" else "terms"]:
                walk(f)
        elif b["op"] != "const":
            need.add(b["var"])
            if "rate" in b:
                need.add(b["rate"])

    for t in terms:
        for b in t["basis"]:
            walk(b)
    return need


# ---------------------------------------------------------------------------
# helpers for building terms and naming their parameters
# ---------------------------------------------------------------------------


def harmonic_amplitude_phase(a_sin: float, a_cos: float) -> tuple[float, float]:
    """``a_sin sin(x) + a_cos cos(x) = A sin(x + psi)``: returns (A, psi), psi in (-pi, pi]."""
    return float(math.hypot(a_sin, a_cos)), float(math.atan2(a_cos, a_sin))


def sin_cos_pair(var: str, k: float, times: Mapping[str, Any] | None = None, *, skew_s: float = 0.0,
                 rate: str | None = None) -> list[dict]:
    """Basis [sin(k var), cos(k var)], each optionally multiplied by the factor spec ``times``; with
    ``skew_s`` != 0 (and the angle's ``rate``) the harmonics are taken at the re-timed angle
    (:func:`retimed_angle`)."""
    s = {"op": "sin", "var": var, "k": k}
    c = {"op": "cos", "var": var, "k": k}
    if skew_s:
        if not rate:
            raise ValueError(f"sin_cos_pair({var!r}): a skew needs the angle's rate signal")
        for b in (s, c):
            b.update(skew_s=float(skew_s), rate=str(rate))
    if times is None:
        return [s, c]
    return [{"op": "prod", "factors": [s, copy.deepcopy(dict(times))]}, {"op": "prod", "factors": [c, copy.deepcopy(dict(times))]}]


def make_term(
    name: str,
    signal: str,
    basis: list[dict],
    coef: Iterable[float],
    *,
    variable: str | None = None,
    order: int | float | None = None,
    form: str = "",
    parameters: Mapping[str, float] | None = None,
) -> dict:
    """Build and validate a term dict (plain Python types, JSON-ready)."""
    term = {
        "name": name,
        "signal": signal,
        "variable": variable,
        "order": None if order is None else (int(order) if float(order).is_integer() else float(order)),
        "form": form,
        "basis": copy.deepcopy(list(basis)),
        "coef": [float(c) for c in coef],
        "parameters": {k: float(v) for k, v in (parameters or {}).items()},
    }
    validate_term(term)
    return term


def terms_to_json(terms: list[Mapping[str, Any]]) -> str:
    """Serialise (validates first)."""
    for j, t in enumerate(terms):
        validate_term(t, f"terms[{j}]")
    return json.dumps(list(terms), indent=1)


def terms_from_json(text: str) -> list[dict]:
    """Parse and validate a JSON list of terms."""
    terms = json.loads(text)
    if not isinstance(terms, list):
        raise ValueError("terms JSON must be a list of term dicts")
    for j, t in enumerate(terms):
        validate_term(t, f"terms[{j}]")
    return terms
