"""Fault classification across missions: healthy / tooth wear / lubrication loss / flexspline stiffness loss / unknown.

**Inputs** (per actuator, as of mission k, causal: only missions <= k): how the actuator has moved away from
its own healthy reference (its first ``healthy_missions`` missions, the ones the ground calibrated on), in
three groups the twin and the onboard monitors give:

* twin sensitivities: which recalibrated parameters move: the per-mission least-squares estimates of the
  Coulomb torque ``T_C`` and of the mesh-loss ratio ``mu_c/mu_g`` (relative change of the median of the
  last ``recent`` missions against the reference median);
* monitor outputs: the friction excess of the onboard friction monitor (run with the ground's references),
  the mean of the missions' max level, and the monitor laws refitted per mission
  (:func:`hd_ground.references.actuator_references` on one mission): the change of the direction-odd
  friction ``b`` (in units of the twin's ``N T_C``) and the log ratio of the torsional compliance;
* features and residuals: log ratios of the output-torque and twist residual RMS, of the kinematic-error
  order ``ke_2x`` and of the lost motion.

**Model**: Gaussian class-conditional densities, each class with its mean and one of three covariance
structures (``covariance``): the pooled within-class covariance (``pooled``, linear discriminant, the default), its
diagonal (``diagonal``), or per class (``class``, quadratic discriminant) shrunk toward the pooled one as a
conjugate prior with ``nu = d + 2`` pseudo-observations, ``S_c = (n_c S_c_hat + nu S_pool) / (n_c + nu)``, so small
classes stay well-conditioned; :func:`fit_across_plants` chooses the structure by leave-one-plant-out
cross-validation when the training data come from several plant types. Equal class priors (a fleet's fault mix is
not the training fleet's). Missing
inputs (a monitor that could not evaluate) are marginalised: the Gaussian of the observed coordinates.
**Unknown** is a broad background class: a Gaussian centred on the training mean with ``background_scale``^2
times the total training covariance and prior ``background_prior``; a point unlikely under every fault
class but not under the broad one (far from all classes) gets its probability mass. Both constants are
set once here, not fitted on the scored data.

Training needs labels (from a simulated fleet's truth: ``bench/bench_fleet_classify.py``); the classifier
itself never sees ``/sim``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

CLASSES = ("healthy", "tooth_wear", "lubrication_loss", "flexspline_stiffness_loss")
LABELS = CLASSES + ("unknown",)
FEATURES = ("d_T_C", "d_mesh_loss", "friction_excess", "d_friction_b", "log_compliance", "max_level",
            "log_Q_rms", "log_twist_rms", "log_ke_2x", "log_lost_motion")
DEFAULT_MODEL = Path(__file__).with_name("default_classifier.json")
#: class covariance structures: shared full (LDA), per class shrunk to the pooled one (QDA), shared diagonal
COVARIANCES = ("pooled", "class", "diagonal")


def _med(rows: Sequence[dict], key: str) -> float:
    v = np.array([r.get(key) if r.get(key) is not None else np.nan for r in rows], float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else math.nan


def _logratio(cur: float, ref: float) -> float:
    return math.log(cur / ref) if (cur > 0 and ref > 0 and math.isfinite(cur) and math.isfinite(ref)) else math.nan


def snapshot_features(stats: Sequence[dict], feats: Sequence[dict], upto: int, healthy_missions: int = 3,
                      recent: int = 3) -> np.ndarray | None:
    """The feature vector (:data:`FEATURES`) of one actuator as of mission ``upto`` (None: no mission after the
    reference yet). ``stats``/``feats``: its ``residual_stats`` and ``features`` rows (any order)."""
    S = sorted((r for r in stats if r["mission_index"] <= upto), key=lambda r: r["mission_index"])
    F = {r["mission_index"]: r for r in feats}
    if len(S) <= healthy_missions:
        return None
    ref, cur = S[:healthy_missions], S[-min(recent, len(S) - healthy_missions):]
    fref = [F.get(r["mission_index"], {}) for r in ref]
    fcur = [F.get(r["mission_index"], {}) for r in cur]
    tc0 = _med(ref, "recal_T_C")
    x = [
        (_med(cur, "recal_T_C") - tc0) / abs(tc0) if (math.isfinite(tc0) and tc0 != 0) else math.nan,
        _med(cur, "recal_mesh_loss_ratio") - _med(ref, "recal_mesh_loss_ratio"),
        _med(cur, "friction_excess"),
        (_med(cur, "fit_friction_b") - _med(ref, "fit_friction_b")) / _med(ref, "fit_friction_scale"),
        _logratio(abs(_med(cur, "fit_compliance")), abs(_med(ref, "fit_compliance"))),  # sign: encoder convention
        float(np.mean([r.get("max_level", 0) or 0 for r in cur])),
        _logratio(_med(cur, "Q_red_rms"), _med(ref, "Q_red_rms")),
        _logratio(_med(cur, "twist_rms"), _med(ref, "twist_rms")),
        _logratio(_med(fcur, "ke_2x"), _med(fref, "ke_2x")),
        _logratio(_med(fcur, "lost_motion"), _med(fref, "lost_motion")),
    ]
    return np.array(x, float)


def _logpdf(x: np.ndarray, mu: np.ndarray, S: np.ndarray) -> tuple[float, float]:
    """(log N(x; mu, S) over x's finite coordinates, squared Mahalanobis distance)."""
    ok = np.isfinite(x)
    if not ok.any():
        return 0.0, 0.0
    d = x[ok] - mu[ok]
    Ss = S[np.ix_(ok, ok)]
    L = np.linalg.cholesky(Ss)
    z = np.linalg.solve(L, d)
    m2 = float(z @ z)
    return -0.5 * m2 - float(np.log(np.diag(L)).sum()) - 0.5 * ok.sum() * math.log(2 * math.pi), m2


class GaussianFaultClassifier:
    """Gaussian class densities (pooled, diagonal or per-class covariance) with a broad background ("unknown") class
    (see the module docstring)."""

    def __init__(self, background_scale: float = 3.0, background_prior: float = 0.02, covariance: str = "pooled"):
        if covariance not in COVARIANCES:
            raise ValueError(f"fault classifier: covariance {covariance!r} must be one of {', '.join(COVARIANCES)} "
                             "('pooled': LDA, 'class': QDA, 'diagonal': the pooled within-class variances only)")
        self.covariance = covariance
        self.background_scale = float(background_scale)
        self.background_prior = float(background_prior)
        self.classes: list[str] = []
        self.means: dict[str, np.ndarray] = {}
        self.covs: dict[str, np.ndarray] = {}
        self.counts: dict[str, int] = {}
        self.mu_all = np.zeros(0)
        self.cov_all = np.zeros((0, 0))
        self.fill: np.ndarray = np.zeros(0)
        self.info: dict[str, Any] = {}

    def fit(self, X: np.ndarray, y: Sequence[str]) -> "GaussianFaultClassifier":
        X = np.asarray(X, float)
        y = np.asarray(list(y))
        if X.ndim != 2 or X.shape[1] != len(FEATURES) or len(X) != len(y):
            raise ValueError(f"fault classifier: X must be (n, {len(FEATURES)}) with one label per row")
        d = X.shape[1]
        # training rows with a missing coordinate: the column median (fit only; prediction marginalises)
        self.fill = np.array([np.nanmedian(c) if np.isfinite(c).any() else 0.0 for c in X.T])
        Xf = np.where(np.isfinite(X), X, self.fill)
        sd = Xf.std(axis=0)
        jitter = np.diag((1e-3 * np.where(sd > 0, sd, 1.0)) ** 2)
        self.classes = [c for c in CLASSES if (y == c).sum() >= 2]
        if len(self.classes) < 2:
            raise ValueError(f"fault classifier: need >= 2 classes with >= 2 rows, got {dict(zip(*np.unique(y, return_counts=True)))}")
        pooled = np.zeros((d, d))
        n_tot = 0
        for c in self.classes:
            Xc = Xf[y == c]
            self.means[c] = Xc.mean(axis=0)
            self.counts[c] = len(Xc)
            pooled += (Xc - self.means[c]).T @ (Xc - self.means[c])
            n_tot += len(Xc)
        pooled = pooled / max(n_tot - len(self.classes), 1) + jitter
        nu = d + 2
        for c in self.classes:
            Xc = Xf[y == c]
            Sc = np.cov(Xc.T, bias=True) if len(Xc) > 1 else np.zeros((d, d))
            if self.covariance == "pooled":
                self.covs[c] = pooled
            elif self.covariance == "diagonal":
                self.covs[c] = np.diag(np.diag(pooled))
            else:
                self.covs[c] = (len(Xc) * Sc + nu * pooled) / (len(Xc) + nu) + jitter
        keep = np.isin(y, self.classes)
        self.mu_all = Xf[keep].mean(axis=0)
        self.cov_all = np.cov(Xf[keep].T) + jitter
        self.info = {"n_train": int(keep.sum()), "counts": self.counts, "features": list(FEATURES)}
        return self

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        """(n, len(LABELS)) probabilities in :data:`LABELS` order (classes absent in training get 0)."""
        X = np.atleast_2d(np.asarray(X, float))
        out = np.zeros((len(X), len(LABELS)))
        pk = (1.0 - self.background_prior) / len(self.classes)
        for i, x in enumerate(X):
            lp = []
            for c in self.classes:
                lp.append(math.log(pk) + _logpdf(x, self.means[c], self.covs[c])[0])
            lp.append(math.log(self.background_prior)
                      + _logpdf(x, self.mu_all, self.background_scale**2 * self.cov_all)[0])
            lp = np.array(lp)
            p = np.exp(lp - lp.max())
            p /= p.sum()
            for c, v in zip(self.classes, p[:-1]):
                out[i, LABELS.index(c)] = v
            out[i, LABELS.index("unknown")] = p[-1]
        return out

    def predict(self, X: np.ndarray) -> list[str]:
        return [LABELS[j] for j in self.predict_proba(X).argmax(axis=1)]

    def to_json(self) -> dict:
        return {"kind": "gaussian_qda_background", "features": list(FEATURES), "classes": self.classes,
                "means": {c: v.tolist() for c, v in self.means.items()},
                "covs": {c: v.tolist() for c, v in self.covs.items()}, "counts": self.counts,
                "mu_all": self.mu_all.tolist(), "cov_all": self.cov_all.tolist(), "fill": self.fill.tolist(),
                "background_scale": self.background_scale, "background_prior": self.background_prior,
                "covariance": self.covariance,
                "info": self.info}

    @classmethod
    def from_json(cls, d: dict, where: str = "fault classifier") -> "GaussianFaultClassifier":
        if d.get("kind") != "gaussian_qda_background" or list(d.get("features", [])) != list(FEATURES):
            raise ValueError(f"{where}: not a fault classifier for features {FEATURES} "
                             f"(kind {d.get('kind')!r}, features {d.get('features')}); retrain it")
        m = cls(d["background_scale"], d["background_prior"], d.get("covariance", "class"))
        m.classes = list(d["classes"])
        m.means = {c: np.asarray(v, float) for c, v in d["means"].items()}
        m.covs = {c: np.asarray(v, float) for c, v in d["covs"].items()}
        m.counts = d.get("counts", {})
        m.mu_all, m.cov_all = np.asarray(d["mu_all"], float), np.asarray(d["cov_all"], float)
        m.fill = np.asarray(d.get("fill", [0.0] * len(FEATURES)), float)
        m.info = d.get("info", {})
        return m

    def save(self, path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1))


def macro_recall(y_true: Sequence[str], y_pred: Sequence[str]) -> float:
    """Mean over the true classes present of the fraction predicted right (balanced accuracy: a fleet's fault mix
    is not the training fleet's, so no class weighs by its count)."""
    yt, yp = np.asarray(list(y_true)), np.asarray(list(y_pred))
    rec = [float(np.mean(yp[yt == c] == c)) for c in CLASSES if (yt == c).any()]
    return float(np.mean(rec)) if rec else math.nan


def fit_across_plants(X: np.ndarray, y: Sequence[str], plants: Sequence[str],
                      candidates: Sequence[str] = COVARIANCES, **kw) -> GaussianFaultClassifier:
    """The classifier fitted on every row, its covariance structure (:data:`COVARIANCES`) chosen by
    leave-one-plant-out cross-validation: each candidate is fitted on all plants but one and scored (macro recall,
    "unknown" counted wrong) on the one left out; the one with the best mean over the plants is kept (ties: the
    earlier candidate). What is chosen is what transfers to a plant the fit has not seen, which is how the classifier
    is used. With fewer than two plants there is nothing to hold out: the first candidate is fitted and
    ``info["covariance_choice"]`` says so."""
    X = np.asarray(X, float)
    y = np.asarray(list(y))
    g = np.asarray([str(v) for v in plants])
    if len(g) != len(y):
        raise ValueError(f"fault classifier: {len(g)} plant labels for {len(y)} rows")
    cands = [str(c) for c in candidates]
    names = sorted(set(g))
    scores: dict[str, dict[str, float]] = {c: {} for c in cands}
    for held in names if len(names) >= 2 else []:
        tr, te = g != held, g == held
        if sum(int((y[tr] == c).sum() >= 2) for c in CLASSES) < 2:
            continue  # the other plants alone cannot be fitted (fewer than two classes with two rows)
        for c in cands:
            m = GaussianFaultClassifier(covariance=c, **kw).fit(X[tr], y[tr])
            scores[c][held] = macro_recall(y[te], m.predict(X[te]))
    mean = {c: float(np.mean(list(v.values()))) if v else math.nan for c, v in scores.items()}
    ok = [c for c in cands if math.isfinite(mean[c])]
    best = max(ok, key=lambda c: (mean[c], -cands.index(c))) if ok else cands[0]
    m = GaussianFaultClassifier(covariance=best, **kw).fit(X, y)
    m.info["covariance_choice"] = ({"rule": "leave-one-plant-out macro recall", "plants": names, "chosen": best,
                                    "mean_macro_recall": mean, "per_plant": scores}
                                   if ok else {"rule": f"no plant could be held out ({', '.join(names)}: one plant, "
                                                       f"or the others alone cannot be fitted): {best}, not chosen"})
    return m


class NearestCentroid:
    """The afternoon baseline: z-scored features, nearest class mean (Euclidean over the observed coordinates)."""

    def fit(self, X, y):
        X = np.asarray(X, float)
        y = np.asarray(list(y))
        self.fill = np.array([np.nanmedian(c) if np.isfinite(c).any() else 0.0 for c in X.T])
        Xf = np.where(np.isfinite(X), X, self.fill)
        self.mu, self.sd = Xf.mean(axis=0), Xf.std(axis=0)
        self.sd[self.sd == 0] = 1.0
        self.classes = [c for c in CLASSES if (y == c).any()]
        self.cent = {c: ((Xf[y == c] - self.mu) / self.sd).mean(axis=0) for c in self.classes}
        return self

    def predict(self, X) -> list[str]:
        out = []
        for x in np.atleast_2d(np.asarray(X, float)):
            ok = np.isfinite(x)
            z = (x - self.mu) / self.sd
            out.append(min(self.classes, key=lambda c: float(np.sum((z[ok] - self.cent[c][ok]) ** 2))))
        return out


def load_classifier(path: str | None = None) -> GaussianFaultClassifier | None:
    """The classifier of ``path`` (or the package default; None if there is none)."""
    p = Path(path) if path else DEFAULT_MODEL
    if not p.is_file():
        if path:
            raise FileNotFoundError(f"{p}: fault classifier file not found")
        return None
    from hd_bag.files import read_json

    d = read_json(p, "fault classifier")
    return GaussianFaultClassifier.from_json(d, str(p))


def classify_history(stats: Sequence[dict], feats: Sequence[dict], model: GaussianFaultClassifier,
                     healthy_missions: int = 3) -> list[dict]:
    """One row per mission after the reference: the class probabilities as of that mission."""
    out = []
    aid = stats[0]["actuator_id"] if stats else ""
    for k in sorted({r["mission_index"] for r in stats}):
        x = snapshot_features(stats, feats, k, healthy_missions)
        if x is None:
            continue
        p = model.predict_proba(x)[0]
        row = {"actuator_id": aid, "mission_index": int(k)}
        row.update({f"p_{c}": float(v) for c, v in zip(LABELS, p)})
        row["label"] = LABELS[int(np.argmax(p))]
        row.update({f"x_{n}": float(v) for n, v in zip(FEATURES, x)})
        out.append(row)
    return out
