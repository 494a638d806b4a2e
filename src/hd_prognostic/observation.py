"""Observation model of the HD health feature: feature = f(wear) with heteroscedastic noise.

``y | h ~ N(mu(h), sigma(h)^2)`` (or Student-t in the filter) with

    mu(h)    = sum_j c_j (h / h_ref)^j          (polynomial, degree 1-3)
    sigma(h) = s0 + s1 (h / h_ref)              (s0, s1 >= 0: spread grows with wear)

fitted from a *training* population: pairs (true wear h from ``/sim/health``,
feature value from the bag signals) of actuators other than the one under
test. The feature may be normalised per actuator by its own beginning-of-life
value (``baseline``: ``none``, ``subtract`` or ``ratio`` of the median over
the first ``n_baseline`` missions): that uses only the unit's own early
observations, which the onboard node has too. Saved as a small JSON that the
prognostic node loads.

``baseline = "state"``: the unit's feature offset ``b`` (its beginning-of-life
level, e.g. the manufacturing kinematic error A2) is not subtracted from a
few early missions but estimated jointly with the wear: ``y = b + mu(h) + e``
with ``mu(0) = 0`` and a population prior ``b ~ N(offset_mean, offset_std^2)``
(per-unit intercepts of the training fit). The filter carries ``b`` as an
exactly marginalised (Rao-Blackwellised) Gaussian per particle (see
:class:`hd_prognostic.models.ArchardWear`), so every mission refines it; a
median of three noisy early missions left a 1-2 um wear bias for the whole
life. ``normalise`` returns the raw feature in this mode.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

BASELINES = ("none", "subtract", "ratio", "state")


@dataclass
class ObservationModel:
    """Heteroscedastic feature-vs-wear model (see module doc). Units: h in m, y in the feature's unit."""

    feature: str = "HF_MTW_IF"
    coef: list[float] = field(default_factory=lambda: [0.0, 1.0])  # mu polynomial in h/h_ref, ascending
    s0: float = 1.0
    s1: float = 0.0
    h_ref: float = 1e-5  # m, scale of the wear axis
    baseline: str = "none"
    n_baseline: int = 3
    h_fail: float = float("nan")  # m, the failure threshold of the training population (median)
    fit_info: dict = field(default_factory=dict)
    #: prior of the Archard model fitted on the same training population
    #: (ArchardWear keyword arguments: log_kappa_mean/std, h0_mean/std, sigma_proc, h_fail) and
    #: ``W_median`` [J], the population's median load-sliding integral per mission.
    degradation: dict = field(default_factory=dict)
    #: optional feature fusion: the observed health index is
    #: ``sum_j fusion_coef[j] * normalise(f_j) + fusion_coef[-1]`` over ``fusion_features``
    #: (a least-squares wear regression fitted on the training population, in m of wear).
    fusion_features: list[str] = field(default_factory=list)
    fusion_coef: list[float] = field(default_factory=list)
    #: ``baseline = "state"``: population prior of the per-unit feature offset b (feature units)
    offset_mean: float = 0.0
    offset_std: float = 0.0

    def __post_init__(self) -> None:
        if self.baseline not in BASELINES:
            raise ValueError(f"ObservationModel.baseline must be one of {BASELINES}, got {self.baseline!r}")
        if not (np.isfinite(self.h_ref) and self.h_ref > 0):
            raise ValueError(f"ObservationModel.h_ref must be > 0, got {self.h_ref!r}")
        if self.s0 < 0 or self.s1 < 0 or not np.isfinite(self.s0 + self.s1):
            raise ValueError(f"ObservationModel: s0, s1 must be finite and >= 0, got {self.s0}, {self.s1}")
        if self.s0 + self.s1 <= 0:
            raise ValueError("ObservationModel: the noise std must be positive somewhere (s0 + s1 > 0)")
        if not (np.isfinite(self.offset_mean) and np.isfinite(self.offset_std) and self.offset_std >= 0):
            raise ValueError("ObservationModel: offset_mean must be finite and offset_std finite and >= 0, "
                             f"got {self.offset_mean!r}, {self.offset_std!r}")

    # ---- evaluation -----------------------------------------------------------
    def mean(self, h: np.ndarray) -> np.ndarray:
        u = np.asarray(h, float) / self.h_ref
        out = np.full_like(u, self.coef[-1])
        for c in self.coef[-2::-1]:  # Horner over the (few) coefficients
            out *= u
            out += c
        return out

    def std(self, h: np.ndarray) -> np.ndarray:
        return self.s0 + self.s1 * np.maximum(np.asarray(h, float), 0.0) / self.h_ref

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Observation function for a particle array (column 0 = wear depth h)."""
        h = x[:, 0] if np.ndim(x) == 2 else x
        return self.mean(h), self.std(h)

    def baselines(self, y: np.ndarray) -> np.ndarray:
        """Causal baseline per mission: median of the first ``n_baseline`` finite values seen so far."""
        y = np.asarray(y, float)
        b = np.full(len(y), np.nan)
        seen: list[float] = []
        for k, v in enumerate(y):  # over missions, not samples
            if np.isfinite(v) and len(seen) < self.n_baseline:
                seen.append(float(v))
            if seen:
                b[k] = float(np.median(seen))
        return b

    def normalise(self, y: np.ndarray) -> np.ndarray:
        """Per-actuator baseline normalisation of a feature series in mission order (causal: the node
        can compute the same value at every mission)."""
        y = np.asarray(y, float)
        if self.baseline in ("none", "state") or len(y) == 0:
            return y
        b = self.baselines(y)
        return y - b if self.baseline == "subtract" else y / b

    def series(self, features: dict[str, np.ndarray]) -> np.ndarray:
        """The observed health index per mission from per-mission feature series (name -> array).

        Without fusion: the normalised ``self.feature``. With fusion: the
        fitted linear combination of the normalised ``fusion_features``
        (NaN where any of them is NaN: that mission is predict-only).
        """
        if not self.fusion_features:
            if self.feature not in features:
                raise KeyError(f"feature {self.feature!r} missing; have {sorted(features)}")
            return self.normalise(features[self.feature])
        missing = [f for f in self.fusion_features if f not in features]
        if missing:
            raise KeyError(f"fusion features {missing} missing; have {sorted(features)}")
        cols = [self.normalise(features[f]) for f in self.fusion_features]
        X = np.column_stack(cols + [np.ones(len(cols[0]))])
        return X @ np.asarray(self.fusion_coef, float)

    @staticmethod
    def fit_fusion(h: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Least-squares coefficients (last = intercept) of wear ``h`` on normalised features ``X``."""
        A = np.column_stack([X, np.ones(len(X))])
        ok = np.all(np.isfinite(A), axis=1) & np.isfinite(h)
        if ok.sum() < A.shape[1] + 2:
            raise ValueError(f"fit_fusion: only {ok.sum()} complete rows for {A.shape[1]} coefficients")
        c, *_ = np.linalg.lstsq(A[ok], h[ok], rcond=None)
        return c

    # ---- fitting --------------------------------------------------------------
    @classmethod
    def fit(cls, h: np.ndarray, y: np.ndarray, feature: str = "HF_MTW_IF", degree: int = 2,
            baseline: str = "none", n_baseline: int = 3, h_fail: float = float("nan"),
            groups: np.ndarray | None = None) -> "ObservationModel":
        """Least-squares mean polynomial, then a linear fit of the scaled absolute residuals for sigma.

        ``h`` and ``y`` are pooled over the training actuators (``y``
        already normalised with the same ``baseline``). sigma is fitted on
        sqrt(pi/2) |residual| (unbiased for a Gaussian) with non-negative
        coefficients (projected least squares).

        ``baseline = "state"`` needs ``groups`` (the training unit of each
        pair): the mean is then ``b_i + sum_{j>=1} c_j u^j`` with one
        intercept ``b_i`` per unit (joint least squares, ``coef[0] = 0``),
        and ``offset_mean``/``offset_std`` are the mean and sample std of
        the ``b_i`` (the prior of an unseen unit's offset).
        """
        h, y = np.asarray(h, float), np.asarray(y, float)
        ok = np.isfinite(h) & np.isfinite(y)
        if ok.sum() < degree + 3:
            raise ValueError(f"ObservationModel.fit: only {ok.sum()} valid (h, y) pairs for degree {degree}")
        h, y = h[ok], y[ok]
        h_ref = float(np.percentile(np.abs(h), 95)) or 1e-6
        u = h / h_ref
        off_mean = off_std = 0.0
        if baseline == "state":
            if groups is None:
                raise ValueError("ObservationModel.fit: baseline 'state' needs the unit of each pair (groups)")
            g = np.asarray(groups)[ok]
            units, gi = np.unique(g, return_inverse=True)
            if len(units) < 2:
                raise ValueError("ObservationModel.fit: baseline 'state' needs >= 2 training units for the offset prior")
            A = np.column_stack([np.eye(len(units))[gi]] + [u**j for j in range(1, degree + 1)])
            sol, *_ = np.linalg.lstsq(A, y, rcond=None)
            b_i = sol[: len(units)]
            coef = np.concatenate([[0.0], sol[len(units):]])
            r = y - A @ sol
            off_mean, off_std = float(np.mean(b_i)), float(np.std(b_i, ddof=1))
        else:
            coef = np.polynomial.polynomial.polyfit(u, y, degree)
            r = y - np.polynomial.polynomial.polyval(u, coef)
        a = np.sqrt(np.pi / 2) * np.abs(r)
        A = np.column_stack([np.ones_like(u), np.maximum(u, 0)])
        s, *_ = np.linalg.lstsq(A, a, rcond=None)
        if s[1] < 0:
            s = np.array([a.mean(), 0.0])
        if s[0] < 0:
            s1, *_ = np.linalg.lstsq(A[:, 1:], a, rcond=None)
            s = np.array([0.0, max(float(s1[0]), 0.0)])
        s0 = max(float(s[0]), 1e-3 * float(np.std(y)) + 1e-300)
        # monotonicity of the mean over the fitted range (reported, not forced)
        grid = np.linspace(0, u.max(), 50)
        mono = bool(np.all(np.diff(np.polynomial.polynomial.polyval(grid, coef)) >= 0))
        info = {"n": int(len(h)), "degree": degree, "rmse": float(np.sqrt(np.mean(r * r))),
                "r2": float(1 - np.sum(r * r) / max(np.sum((y - y.mean()) ** 2), 1e-300)),
                "h_max": float(h.max()), "mean_monotone_on_range": mono}
        if baseline == "state":
            info["offset_per_unit"] = [float(v) for v in b_i]
            s0 = max(s0, 1e-6 * off_std)
        return cls(feature=feature, coef=[float(c) for c in coef], s0=s0, s1=float(s[1]), h_ref=h_ref,
                   baseline=baseline, n_baseline=n_baseline, h_fail=float(h_fail), fit_info=info,
                   offset_mean=off_mean, offset_std=max(off_std, 1e-300) if baseline == "state" else 0.0)

    # ---- persistence ----------------------------------------------------------
    def to_json(self, path: str | Path) -> Path:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        d = asdict(self)
        d["kind"] = "hd_prognostic.ObservationModel"
        d["version"] = 1
        p.write_text(json.dumps(d, indent=2))
        return p

    @classmethod
    def from_json(cls, path: str | Path) -> "ObservationModel":
        from hd_bag.files import read_json

        p = Path(path)
        d = read_json(p, "observation-model JSON")
        if d.get("kind") != "hd_prognostic.ObservationModel":
            raise ValueError(f"{p}: not an hd_prognostic observation model (kind={d.get('kind')!r})")
        d.pop("kind", None)
        d.pop("version", None)
        try:
            return cls(**d)
        except TypeError as e:
            raise ValueError(f"{p}: bad observation-model fields ({e})") from e
