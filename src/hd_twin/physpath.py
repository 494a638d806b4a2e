"""The twin's physics path: the torque balance identified from the training data.

The twin predicts ``Q_red = Q_phys + g * remainder``: ``Q_phys`` is the motor-side
torque balance identified on the training missions by :mod:`hd_twin.identify`
(linear coefficients by least squares, nonlinear shape parameters such as the
friction transition width by its profile search, with uncertainties; the same
code the discovery uses), the LSTM learns the remainder, and the gate ``g`` in
[0, 1] is chosen on the held-out validation units of the training data so that
no validation unit gets worse than the physics path alone (see
:func:`choose_gate`). This module holds only the adapter: signals from the
twin's segments, fit, predict, serialisation. It never re-implements the
identification.

``kind``: ``"identified"`` (the default when :mod:`hd_twin.identify` is
importable) or ``"none"`` (no physics path: ``Q_phys = 0``, the network predicts
the whole torque, as models before this structure did).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

KINDS = ("identified", "none", "auto")


def identify_available() -> bool:
    try:
        from . import identify  # noqa: F401, PLC0415
    except ImportError:
        return False
    return True


def signals_from_X(X: np.ndarray, dt: float, temperature: np.ndarray | None = None, Q_red: np.ndarray | None = None,
                   t0: float = 0.0) -> dict[str, np.ndarray]:
    """The identification's signal dict from the twin's raw input rows ``X[n, 7]`` (hd_twin.data.RAW_INPUTS)."""
    X = np.asarray(X, dtype=np.float64)
    n = len(X)
    sig = {"t": t0 + np.arange(n) * dt, "theta_m": X[:, 0], "omega_m": X[:, 1], "tau_m": X[:, 2],
           "theta_f": X[:, 3], "omega_f": X[:, 4]}
    sig["temperature"] = X[:, 5] if temperature is None else np.asarray(temperature, dtype=np.float64)
    sig["Q_red"] = np.full(n, np.nan) if Q_red is None else np.asarray(Q_red, dtype=np.float64)
    return sig


def segment_signals(seg) -> dict[str, np.ndarray]:
    """Signal dict of one :class:`hd_twin.data.Segment` (model rate; Q_red NaN where masked)."""
    return signals_from_X(seg.X, seg.dt, seg.temperature, np.where(seg.mask, seg.Q_red, np.nan))


@dataclass
class PhysicsPath:
    """The identified torque balance as the twin's physics path (``kind="none"``: zero)."""

    kind: str = "none"
    identified: Any = None  # hd_twin.identify.Identified
    notes: list[str] = field(default_factory=list)

    @classmethod
    def fit(cls, segs: Sequence, kind: str = "auto") -> "PhysicsPath":
        """Identify ``Q_red`` from the motor-side signals of the training segments (one dict per segment)."""
        if kind not in KINDS:
            raise ValueError(f"physics path must be one of {KINDS}, got {kind!r}")
        if kind == "none":
            return cls("none")
        if not identify_available():
            if kind == "identified":
                raise ValueError("physics path 'identified' needs hd_twin.identify, which is not installed in this tree")
            return cls("none", notes=["hd_twin.identify not available: no physics path (the network predicts Q_red)"])
        from .identify import identify_torque_balance  # noqa: PLC0415

        idf = identify_torque_balance([segment_signals(s) for s in segs], target="Q_red")
        return cls("identified", idf, list(getattr(idf, "notes", []) or []))

    @property
    def active(self) -> bool:
        return self.kind == "identified" and self.identified is not None

    def _predict(self, sig: dict) -> np.ndarray:
        kw = {}
        try:  # a causal evaluation (when identify offers one) makes streaming equal batch exactly
            if "causal" in inspect.signature(self.identified.predict).parameters:
                kw["causal"] = True
        except (TypeError, ValueError):  # pragma: no cover - builtins without a signature
            pass
        q = np.asarray(self.identified.predict(sig, **kw), dtype=np.float64)
        if q.shape != sig["t"].shape:
            raise ValueError(f"identified physics path returned shape {q.shape} for {sig['t'].shape} samples")
        return q

    def predict_signals(self, sig: dict) -> np.ndarray:
        """Q_phys [N*m] on a signal dict that carries its derivative (``alpha_m``, when the balance has that
        column): the streaming twin's FIR derivative (:mod:`hd_twin.streamfir`); the columns are pointwise."""
        if not self.active:
            return np.zeros(len(sig["t"]))
        q = np.asarray(self.identified.predict(sig), dtype=np.float64)
        if q.shape != sig["t"].shape:
            raise ValueError(f"identified physics path returned shape {q.shape} for {sig['t'].shape} samples")
        return q

    def predict_segment(self, seg) -> np.ndarray:
        """Q_phys [N*m] on one segment (zeros when inactive)."""
        if not self.active:
            return np.zeros(seg.n)
        return self._predict(segment_signals(seg))

    def predict_X(self, X: np.ndarray, dt: float, t0: float = 0.0) -> np.ndarray:
        """Q_phys [N*m] on raw input rows at the model rate (streaming)."""
        if not self.active:
            return np.zeros(len(X))
        sig = signals_from_X(X, dt, t0=t0)
        if len(X) < 3:  # the first samples after a reset: no derivative yet, taken as zero
            sig["alpha_m"] = np.zeros(len(X))
            sig["alpha_f"] = np.zeros(len(X))
        return self._predict(sig)

    @property
    def causal(self) -> bool:
        if not self.active:
            return True
        try:
            return "causal" in inspect.signature(self.identified.predict).parameters
        except (TypeError, ValueError):  # pragma: no cover
            return False

    def to_dict(self) -> dict:
        return {"kind": self.kind, "identified": self.identified.to_dict() if self.active else None,
                "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: dict | None) -> "PhysicsPath":
        if not d or d.get("kind", "none") == "none":
            return cls("none", notes=list((d or {}).get("notes", [])))
        if d["kind"] != "identified":
            raise ValueError(f"model config: unknown physics path kind {d['kind']!r}")
        if not identify_available():
            raise ValueError("this model's physics path was identified with hd_twin.identify, which is not installed")
        from .identify import Identified  # noqa: PLC0415

        return cls("identified", Identified.from_dict(d["identified"]), list(d.get("notes", [])))

    def three_body(self, params, z_min: float = 3.0):
        """The paper's input-side parameters the identified balance determines: (params, report).

        Q_red ~ a tau_m + b alpha_m + c tanh(omega_m / w) + d omega_m reads a = N eta, b = -N eta J_eq
        (J_eq = J_in + J_CS / N^2),
        c = -N eta T_C, d = -N eta b_visc, w = eps_omega (PHYSICS.md 2.5 with the motor-side balance);
        each is taken over only when its coefficient is identified (|coef| >= ``z_min`` standard
        deviations), it has the physical sign and it lies inside the parameter bounds; the rest keep
        their prior. J_WG and J_rotor keep their ratio. The efficiency eta = a / N is reported.
        """
        import dataclasses as dc  # noqa: PLC0415

        from .physics import _BOUNDS  # noqa: PLC0415

        rep: dict = {"taken": {}, "kept": {}}
        if not self.active:
            return params, rep
        idf = self.identified
        co = dict(zip(idf.names, np.asarray(idf.coef, float)))
        cov = np.asarray(idf.cov, float)
        sd = dict(zip(idf.names, np.sqrt(np.clip(np.diag(cov), 0, None)))) if cov.ndim == 2 else {}
        a = co.get("tau_m")
        if a is None or not a > 0 or not abs(a) >= z_min * sd.get("tau_m", np.inf):
            rep["kept"]["all"] = "load-path coefficient not identified"
            return params, rep
        rep["eta"] = a / params.N
        cand = {}
        if "alpha_m" in co:
            # the motor-side balance sees J_eq = J_in + J_CS / N^2 (the output inertia, reflected)
            cand["J_in"] = (-co["alpha_m"] / a - params.J_CS / params.N**2,
                            abs(co["alpha_m"]) >= z_min * sd.get("alpha_m", np.inf))
        if "coulomb" in co:
            cand["T_C"] = (-co["coulomb"] / a, abs(co["coulomb"]) >= z_min * sd.get("coulomb", np.inf))
        if "omega_m" in co:
            cand["b_visc"] = (-co["omega_m"] / a, abs(co["omega_m"]) >= z_min * sd.get("omega_m", np.inf))
        w = (getattr(idf, "shape", {}) or {}).get("width")
        if w is not None:
            cand["eps_omega"] = (float(w), bool((getattr(idf, "identified", {}) or {}).get("width", False)))
        kw = {}
        for name, (v, ok) in cand.items():
            lo, hi = _BOUNDS.get(name, (0.0, np.inf)) if name != "J_in" else (1e-12, 20.0)
            if ok and np.isfinite(v) and lo < v <= hi:
                rep["taken"][name] = float(v)
                if name == "J_in":
                    f = v / params.J_in
                    kw["J_WG"], kw["J_rotor"] = params.J_WG * f, params.J_rotor * f
                else:
                    kw[name] = float(v)
            else:
                rep["kept"][name] = f"identified value {v:.4g} not identified, of the wrong sign or out of bounds"
        if "T_C" in kw and params.T_S > 0:
            kw["T_S"] = max(params.T_S * kw["T_C"] / params.T_C, kw["T_C"])  # keep the static/Coulomb ratio
        try:
            return dc.replace(params, **kw).validate("parameters from the identified balance"), rep
        except ValueError as e:
            rep["kept"]["all"] = str(e)
            rep["taken"] = {}
            return params, rep

    def summary(self) -> dict:
        """Names, coefficients with standard deviations and shape parameters (for metrics/show)."""
        if not self.active:
            return {"kind": self.kind}
        idf = self.identified
        coef = np.asarray(idf.coef, float)
        cov = np.asarray(getattr(idf, "cov", np.full((len(coef), len(coef)), np.nan)), float)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None)) if cov.shape == (len(coef), len(coef)) else np.full(len(coef), np.nan)
        return {"kind": self.kind, "terms": {str(n): {"coef": float(c), "sd": float(s)} for n, c, s in zip(idf.names, coef, sd)},
                "shape": {str(k): float(v) for k, v in (getattr(idf, "shape", {}) or {}).items()},
                "shape_sd": {str(k): float(v) for k, v in (getattr(idf, "shape_sd", {}) or {}).items()}}


def choose_gate(y: Sequence[np.ndarray], q_phys: Sequence[np.ndarray], rem: Sequence[np.ndarray]) -> tuple[float, dict]:
    """Gate g in [0, 1] on the learned remainder from held-out groups (validation units).

    Per group u the squared error of ``q_phys + g rem`` is a parabola in g with its
    minimum at g_u = <y - q_phys, rem> / <rem, rem>; for every g in [0, max(0, g_u)] that
    group is no worse than the physics path alone (g = 0). ``g = clip(min_u g_u, 0, 1)``
    is therefore the largest gate (up to 1) that makes no held-out group worse; a
    remainder that hurts any group is switched off (g = 0). Returns (g, details).
    """
    gs, det = [], []
    for yt, qp, r in zip(y, q_phys, rem):
        ok = np.isfinite(yt) & np.isfinite(qp) & np.isfinite(r)
        e, rr = (yt - qp)[ok], r[ok]
        den = float(rr @ rr)
        g_u = float(e @ rr) / den if den > 0 else 0.0
        gs.append(g_u)
        det.append({"n": int(ok.sum()), "g_opt": g_u, "rmse_physics": float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")})
    if not gs:
        return 0.0, {"groups": [], "rule": "no validation group: remainder off"}
    g = float(np.clip(min(gs), 0.0, 1.0))
    return g, {"groups": det, "rule": "g = clip(min over held-out groups of the per-group optimum, 0, 1)"}
