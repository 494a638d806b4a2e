"""Particle filter (sequential importance resampling), vectorised over particles.

Pure numpy; the same object runs in the prognostic node, in batch
(``hdphm prognose``) and in tests. One step is ``predict(u)`` (propagate every
particle through the degradation model with exposure ``u``) then
``update(z)`` (reweight by the observation likelihood). A NaN or missing
observation makes the step predict-only. Resampling (systematic, stratified,
residual or multinomial) runs when the effective sample size falls below
``ess_threshold * n``; after resampling the parameter columns are roughened
(Gordon, Salmond & Smith 1993) so the augmented parameters do not collapse
onto a few values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammaln

from hd_prognostic.models import DegradationModel

RESAMPLERS = ("systematic", "stratified", "residual", "multinomial")
LIKELIHOODS = ("gaussian", "student_t")


# ---- resampling: each returns indices of shape (n,) ------------------------
def systematic_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One uniform offset, n evenly spaced pointers (lowest variance, O(n))."""
    n = len(w)
    u = (rng.random() + np.arange(n)) / n
    c = np.cumsum(w)
    c[-1] = 1.0
    return np.searchsorted(c, u, side="right").clip(0, n - 1)


def stratified_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One uniform draw inside each of n equal strata."""
    n = len(w)
    u = (rng.random(n) + np.arange(n)) / n
    c = np.cumsum(w)
    c[-1] = 1.0
    return np.searchsorted(c, u, side="right").clip(0, n - 1)


def multinomial_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    n = len(w)
    c = np.cumsum(w)
    c[-1] = 1.0
    return np.searchsorted(c, rng.random(n), side="right").clip(0, n - 1)


def residual_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """floor(n w_i) deterministic copies, the remainder drawn multinomially on the residual weights."""
    n = len(w)
    counts = np.floor(n * w).astype(np.int64)
    idx_det = np.repeat(np.arange(n), counts)
    n_rest = n - len(idx_det)
    if n_rest == 0:
        return idx_det
    res = n * w - counts
    res = res / res.sum()
    return np.concatenate([idx_det, multinomial_resample(res, rng)[:n_rest]])


_RESAMPLE_FN = {
    "systematic": systematic_resample,
    "stratified": stratified_resample,
    "residual": residual_resample,
    "multinomial": multinomial_resample,
}


def resample(w: np.ndarray, rng: np.random.Generator, scheme: str = "systematic") -> np.ndarray:
    """Indices of the resampled particles for normalised weights ``w``."""
    if scheme not in _RESAMPLE_FN:
        raise ValueError(f"unknown resampling scheme {scheme!r}; one of {RESAMPLERS}")
    return _RESAMPLE_FN[scheme](w, rng)


def log_likelihood(z: float, mean: np.ndarray, std: np.ndarray, kind: str = "gaussian", nu: float = 4.0) -> np.ndarray:
    """Log-density of observation ``z`` per particle (Gaussian or Student-t with ``nu`` dof)."""
    std = np.maximum(std, 1e-300)
    r = (z - mean) / std
    if kind == "gaussian":
        return -0.5 * r * r - np.log(std) - 0.5 * np.log(2 * np.pi)
    if kind == "student_t":
        c = gammaln(0.5 * (nu + 1)) - gammaln(0.5 * nu) - 0.5 * np.log(nu * np.pi)
        return c - np.log(std) - 0.5 * (nu + 1) * np.log1p(r * r / nu)
    raise ValueError(f"unknown likelihood {kind!r}; one of {LIKELIHOODS}")


@dataclass
class StepInfo:
    """What one filter step did (kept in ``ParticleFilter.history`` when asked)."""

    observed: bool
    ess: float
    resampled: bool
    log_evidence: float


class ParticleFilter:
    """SIR particle filter over a :class:`DegradationModel`.

    Parameters
    ----------
    model : the degradation model (propagate / observe / sample_prior).
    n_particles : number of particles.
    seed : seed or ``numpy.random.Generator`` (the filter is reproducible).
    resampling : one of ``RESAMPLERS``.
    ess_threshold : resample when ESS < ``ess_threshold * n`` (0..1].
    roughening : Gordon's constant K; jitter std per parameter column is
        ``K * range * n^(-1/d)`` after each resampling (0 disables).
    likelihood : ``gaussian`` or ``student_t`` (robust to outliers).
    nu : Student-t degrees of freedom.
    kernel : ``"gordon"`` (roughening as above) or ``"liu_west"``: after
        resampling, parameter columns move by the Liu & West (2001)
        shrinkage kernel ``a theta_i + (1 - a) mean + sqrt(1 - a^2) std eps``
        with ``a = (3 delta - 1) / (2 delta)``, discount ``delta`` (default
        0.98): the particle cloud is rejuvenated without inflating the
        parameter posterior's mean or variance (Gordon roughening inflates
        it at every resampling; a static parameter then never settles, and
        without jitter it collapses onto a few prior draws).
    discount : Liu-West discount factor delta in (0, 1].
    """

    def __init__(
        self,
        model: DegradationModel,
        n_particles: int = 2000,
        seed: int | np.random.Generator | None = 0,
        resampling: str = "systematic",
        ess_threshold: float = 0.5,
        roughening: float = 0.1,
        likelihood: str = "gaussian",
        nu: float = 4.0,
        particles: np.ndarray | None = None,
        kernel: str = "gordon",
        discount: float = 0.98,
    ) -> None:
        if kernel not in ("gordon", "liu_west"):
            raise ValueError(f"unknown parameter kernel {kernel!r}; 'gordon' or 'liu_west'")
        if not (0 < discount <= 1):
            raise ValueError(f"discount must be in (0, 1], got {discount}")
        self.kernel = kernel
        self.discount = float(discount)
        if resampling not in RESAMPLERS:
            raise ValueError(f"unknown resampling scheme {resampling!r}; one of {RESAMPLERS}")
        if likelihood not in LIKELIHOODS:
            raise ValueError(f"unknown likelihood {likelihood!r}; one of {LIKELIHOODS}")
        if not (0 < ess_threshold <= 1):
            raise ValueError(f"ess_threshold must be in (0, 1], got {ess_threshold}")
        if int(n_particles) < 2:
            raise ValueError(f"n_particles must be >= 2, got {n_particles}")
        if roughening < 0 or not np.isfinite(roughening):
            raise ValueError(f"roughening must be finite and >= 0, got {roughening}")
        self.model = model
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.resampling = resampling
        self.ess_threshold = float(ess_threshold)
        self.roughening = float(roughening)
        self.likelihood = likelihood
        self.nu = float(nu)
        if particles is None:
            particles = model.sample_prior(int(n_particles), self.rng)
        self.x = model.check_state(particles).copy()
        self.n = len(self.x)
        self.logw = np.full(self.n, -np.log(self.n))
        self._w_cache: tuple[np.ndarray, np.ndarray] | None = None
        self.n_steps = 0
        self.n_resample = 0
        self.last: StepInfo | None = None

    # ---- weights -----------------------------------------------------------
    @property
    def weights(self) -> np.ndarray:
        """Normalised weights (cached until the log-weights change)."""
        lw = self.logw
        if self._w_cache is None or self._w_cache[0] is not lw:
            w = np.exp(lw - lw.max())
            self._w_cache = (lw, w / w.sum())
        return self._w_cache[1]

    def ess(self) -> float:
        w = self.weights
        return float(1.0 / np.dot(w, w))

    # ---- steps ---------------------------------------------------------------
    def predict(self, u) -> None:
        """Propagate every particle one step with exposure ``u``."""
        self.x = self.model.propagate(self.x, u, self.rng)
        self.n_steps += 1

    def update(self, z) -> StepInfo:
        """Reweight by observation ``z``; NaN/None/inf -> no update (predict-only step)."""
        if z is None or not np.isfinite(z):
            self.last = StepInfo(False, self.ess(), False, 0.0)
            return self.last
        if getattr(self.model, "custom_likelihood", False):  # the model's own (e.g. asymmetric) likelihood
            mean = std = None
            ll = self.model.log_likelihood(float(z), self.x)
        else:
            mean, std = self.model.observe(self.x)
            ll = log_likelihood(float(z), mean, std, self.likelihood, self.nu)
        ll = np.where(np.isfinite(ll), ll, -np.inf)
        lw = self.logw + ll
        m = lw.max()
        if not np.isfinite(m):
            # every particle is impossible under z: keep the prior weights and say so
            self.last = StepInfo(True, self.ess(), False, -np.inf)
            return self.last
        assimilate = getattr(self.model, "assimilate", None)
        if assimilate is not None and mean is not None:
            # Rao-Blackwellised columns (e.g. the feature offset): exact per-particle update after weighting
            assimilate(self.x, float(z), mean, std, self.nu if self.likelihood == "student_t" else None)
        w = np.exp(lw - m)
        sw = w.sum()
        log_ev = float(m + np.log(sw))
        self.logw = lw - log_ev
        w /= sw
        self._w_cache = (self.logw, w)  # the normalised weights, without a second exp
        ess = float(1.0 / np.dot(w, w))
        resampled = False
        if ess < self.ess_threshold * self.n:
            self._resample()
            resampled = True
        self.last = StepInfo(True, ess, resampled, log_ev)
        return self.last

    def step(self, u, z) -> StepInfo:
        self.predict(u)
        return self.update(z)

    def _resample(self) -> None:
        idx = resample(self.weights, self.rng, self.resampling)
        self.x = self.x[idx]
        self.logw = np.full(self.n, -np.log(self.n))
        self.n_resample += 1
        pm = np.asarray(self.model.param_mask, bool)
        moved = getattr(self.model, "params_moved", None)
        old = self.x[:, pm].copy() if (moved is not None and pm.any()) else None
        if self.kernel == "liu_west" and pm.any():
            # mean and std of the resampled (equally weighted) parameter cloud
            th = self.x[:, pm]
            mu, sd = th.mean(axis=0), th.std(axis=0)
            a = (3.0 * self.discount - 1.0) / (2.0 * self.discount)
            self.x[:, pm] = a * th + (1.0 - a) * mu + np.sqrt(max(1.0 - a * a, 0.0)) * sd * \
                self.rng.standard_normal(th.shape)
        elif self.roughening > 0 and pm.any():
            # dimension of the sampled state (Rao-Blackwellised columns are not sampled)
            d = max(self.x.shape[1] - int(getattr(self.model, "n_marginalised", 0)), 1)
            span = np.ptp(self.x[:, pm], axis=0)
            sig = self.roughening * span * self.n ** (-1.0 / d)
            self.x[:, pm] += sig * self.rng.standard_normal((self.n, int(pm.sum())))
        if old is not None:
            moved(old, self.x)  # let the model keep states that depend on the parameters consistent

    # ---- summaries -----------------------------------------------------------
    def mean(self) -> np.ndarray:
        return self.weights @ self.x

    def std(self) -> np.ndarray:
        w = self.weights
        mu = w @ self.x
        return np.sqrt(np.maximum(w @ (self.x - mu) ** 2, 0.0))

    def quantiles(self, q, column: int = 0) -> np.ndarray:
        return weighted_quantile(self.x[:, column], self.weights, q)

    def resampled_particles(self) -> np.ndarray:
        """An equally weighted copy of the particle set (for plots and RUL)."""
        return self.x[resample(self.weights, self.rng, "systematic")]


def weighted_quantile(v: np.ndarray, w: np.ndarray | None, q) -> np.ndarray:
    """Quantiles ``q`` (0..1) of samples ``v`` with weights ``w`` (inverse of the weighted CDF, midpoint rule)."""
    v = np.asarray(v, float)
    q = np.atleast_1d(np.asarray(q, float))
    if w is None:
        return np.quantile(v, q)
    o = np.argsort(v)
    vs, ws = v[o], np.asarray(w, float)[o]
    c = np.cumsum(ws) - 0.5 * ws
    c /= ws.sum()
    return np.interp(q, c, vs)
