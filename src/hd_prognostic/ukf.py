"""Unscented Kalman filter baseline on the same :class:`DegradationModel`.

Merwe scaled sigma points (alpha, beta, kappa), the model's noise-free
propagation (``rng=None``) as the process function, its
``process_cov`` as the additive process-noise covariance and its
``observe`` (mean, std at the predicted mean) as the measurement function
and noise. RUL from the UKF: sample the Gaussian posterior and propagate the
samples with :func:`hd_prognostic.rul.rul_distribution` (so the RUL step is
the same as the PF's; only the state estimate differs).
"""

from __future__ import annotations

import numpy as np

from hd_prognostic.models import DegradationModel


def merwe_weights(n: int, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> tuple[float, np.ndarray, np.ndarray]:
    """Merwe scaled sigma-point weights for an ``n``-state filter: ``(c, wm, wc)`` with ``c = n + lambda``
    (sigma points at ``x +- columns of sqrt(c P)``), ``wm`` the mean and ``wc`` the covariance weights."""
    lam = alpha**2 * (n + kappa) - n
    c = n + lam
    wm = np.full(2 * n + 1, 0.5 / c)
    wc = wm.copy()
    wm[0] = lam / c
    wc[0] = lam / c + (1 - alpha**2 + beta)
    return c, wm, wc


class UnscentedKalmanFilter:
    def __init__(self, model: DegradationModel, x0: np.ndarray, P0: np.ndarray, alpha: float = 0.5,
                 beta: float = 2.0, kappa: float = 0.0) -> None:
        self.model = model
        self.x = np.asarray(x0, float).copy()
        self.P = np.asarray(P0, float).copy()
        self.n = n = len(self.x)
        self.c, self.wm, self.wc = merwe_weights(n, alpha, beta, kappa)

    @classmethod
    def from_prior(cls, model: DegradationModel, n_samples: int = 20000, seed: int = 0, **kw) -> "UnscentedKalmanFilter":
        s = model.sample_prior(n_samples, np.random.default_rng(seed))
        return cls(model, s.mean(0), np.cov(s.T), **kw)

    def sigma_points(self) -> np.ndarray:
        P = 0.5 * (self.P + self.P.T)
        try:
            S = np.linalg.cholesky(self.c * P)
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(self.c * P)
            S = V @ np.diag(np.sqrt(np.maximum(w, 1e-300)))
        return np.vstack([self.x, self.x + S.T, self.x - S.T])

    def predict(self, u) -> None:
        X = self.model.propagate(self.sigma_points(), u, None)
        self.x = self.wm @ X
        d = X - self.x
        self.P = (self.wc[:, None] * d).T @ d + self.model.process_cov(self.x, u)

    def update(self, z) -> None:
        if z is None or not np.isfinite(z):
            return
        X = self.sigma_points()
        Zm, _ = self.model.observe(X)
        zm = self.wm @ Zm
        _, r_std = self.model.observe(self.x[None, :])
        S = self.wc @ (Zm - zm) ** 2 + float(r_std[0]) ** 2
        C = (self.wc[:, None] * (X - self.x)).T @ (Zm - zm)
        K = C / S
        self.x = self.x + K * (float(z) - zm)
        self.P = self.P - np.outer(K, K) * S

    def step(self, u, z) -> None:
        self.predict(u)
        self.update(z)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        P = 0.5 * (self.P + self.P.T)
        w, V = np.linalg.eigh(P)
        L = V @ np.diag(np.sqrt(np.maximum(w, 0.0)))
        return self.x + rng.standard_normal((n, self.n)) @ L.T
