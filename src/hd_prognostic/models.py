"""Degradation (state) models behind one interface, vectorised over particles.

Every model works on a particle array ``x`` of shape ``(n, n_states)`` and an
exogenous *exposure* ``u`` per step (scalar or shape ``(n,)``): what drives
degradation during the step. The same filter (:mod:`hd_prognostic.pf`), UKF
(:mod:`hd_prognostic.ukf`) and RUL propagation (:mod:`hd_prognostic.rul`) run
every model.

Models
------
* :class:`ArchardWear` -- harmonic-drive flank wear depth ``h`` [m] grown by
  Archard's law with the mission's load-sliding integral
  ``W = int |Q_red| |omega_m| dt`` [J]; the lumped wear coefficient
  ``kappa = k_D / (pi r_m n_eff cos(alpha) b)`` [m/J] is an augmented state
  (stored as ``log_kappa``) so it is learned per actuator (PHYSICS.md section 4).
* :class:`ExponentialFade` -- capacity ``C`` [Ah] fading as
  ``C_{k+1} = C_k exp(b dk)`` with the fade rate ``b`` [1/cycle] augmented.
* :class:`ParisCrack` -- crack length ``a`` [m] grown by Paris' law
  ``da/dN = C' a^{m/2}`` (``C' = C (Y dsigma sqrt(pi))^m``), exact closed-form
  integration over any step, ``log C'`` augmented, ``m`` fixed per material.

A model's observation ``observe(x) -> (mean, std)`` is the distribution of the
measured feature given the state; it is either built in (capacity, crack
length) or an :class:`hd_prognostic.observation.ObservationModel` attached to
the model (the HD health feature as a function of wear).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

ObserveFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


class DegradationModel:
    """Generic interface of a degradation model (subclass and fill in).

    Attributes
    ----------
    state_names : names of the state columns.
    param_mask : bool per column, True for augmented *parameters* (they get
        roughening in the particle filter, and random-walk noise only).
    health_index : the column that the failure threshold applies to.
    threshold : failure threshold on ``x[:, health_index]`` (state units).
    increasing : True when failure is ``x >= threshold`` (wear, crack),
        False when it is ``x <= threshold`` (capacity fade).
    time_unit : name of the unit of the RUL time axis (``mission``, ``cycle``).
    """

    state_names: tuple[str, ...] = ()
    param_mask: np.ndarray = np.zeros(0, bool)
    health_index: int = 0
    threshold: float = np.inf
    increasing: bool = True
    time_unit: str = "step"
    observe_fn: ObserveFn | None = None
    #: True when the model supplies ``log_likelihood(z, x)`` for the filter instead of (mean, std)
    custom_likelihood: bool = False

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    # ---- to implement ------------------------------------------------------
    def propagate(self, x: np.ndarray, u, rng: np.random.Generator | None) -> np.ndarray:
        """State after one step with exposure ``u``; ``rng=None`` gives the noise-free mean map."""
        raise NotImplementedError

    def sample_prior(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` particles drawn from the prior, shape ``(n, n_states)``."""
        raise NotImplementedError

    def process_cov(self, x_mean: np.ndarray, u) -> np.ndarray:
        """Additive-Gaussian equivalent of the process noise at ``x_mean`` (for the UKF)."""
        raise NotImplementedError

    # ---- shared ------------------------------------------------------------
    def observe(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation of the observation for each particle."""
        if self.observe_fn is None:
            raise RuntimeError(f"{type(self).__name__} has no observation model attached")
        return self.observe_fn(x)

    def health(self, x: np.ndarray) -> np.ndarray:
        return x[..., self.health_index]

    def failed(self, x: np.ndarray) -> np.ndarray:
        """Boolean per particle: is the failure threshold reached."""
        hv = self.health(x)
        return hv >= self.threshold if self.increasing else hv <= self.threshold

    def check_state(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != self.n_states:
            raise ValueError(f"{type(self).__name__}: particles must have shape (n, {self.n_states}), got {x.shape}")
        return x


def _positive(name: str, v: float) -> float:
    v = float(v)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a finite positive number, got {v!r}")
    return v


@dataclass
class ArchardWear(DegradationModel):
    """Mean flank wear depth ``h`` [m] of the harmonic-drive mesh under Archard's law.

    ``h_{k+1} = h_k + kappa_k W_k eps_k`` with ``W_k`` the load-sliding
    integral of the step [J] (``int |Q_red| |omega_m| dt``), ``kappa`` [m/J]
    the lumped wear coefficient and ``eps_k`` a mean-one lognormal process
    noise (``sigma_proc``) that keeps wear monotone. ``log_kappa`` follows a
    random walk with std ``sigma_log_kappa`` per step (joint state-parameter
    estimation). The prior is lognormal on kappa (unit-to-unit scatter of
    k_D, PHYSICS.md section 4: sigma_ln 0.3-0.5) and normal on the initial
    wear.

    Per-unit feature offset (``offset_std > 0``): the measured feature is
    ``y = b + mu(h) + e``, ``b`` the unit's beginning-of-life feature level
    with prior ``N(offset_mean, offset_std^2)``. ``offset_mode``:

    * ``"rb"`` (particle filter): ``b`` is marginalised exactly per
      particle (Rao-Blackwellisation): columns ``b`` (posterior mean) and
      ``P_b`` (posterior variance) hold a Kalman estimate conditioned on
      that particle's wear history; :meth:`observe` gives the predictive
      ``N(b + mu(h), sigma(h)^2 + P_b)`` and :meth:`assimilate` (called by
      the filter after weighting) updates ``b, P_b``. Resampling copies
      them with the particle; no roughening is needed.
    * ``"state"`` (UKF): ``b`` is one plain static state column.
    """

    h_fail: float = 30e-6  # m
    log_kappa_mean: float = np.log(1e-15)  # ln(m/J)
    log_kappa_std: float = 0.6
    h0_mean: float = 0.0  # m
    h0_std: float = 0.5e-6  # m
    sigma_proc: float = 0.2  # lognormal std of the per-step increment
    sigma_log_kappa: float = 0.02  # random-walk std of ln kappa per step
    observe_fn: ObserveFn | None = None
    time_unit: str = "mission"
    h_fail_std: float = 0.0  # m, unit-to-unit scatter of the failure wear (random threshold in the RUL)
    offset_mean: float = 0.0  # feature units, prior mean of the per-unit feature offset b
    offset_std: float = 0.0  # feature units, prior std of b (0: no offset state)
    offset_mode: str = "rb"  # "rb" (marginalised per particle, PF) or "state" (plain column, UKF)
    #: kappa as the unit's life-average wear coefficient: wear is h = h0 + kappa U with U the integrated
    #: exposure, so any move of ln kappa (random walk, kernel jitter after resampling) rescales the wear
    #: accumulated so far instead of changing only future increments. For a wear law with a fixed
    #: coefficient this keeps (h, kappa) consistent: a particle whose kappa is corrected is not left
    #: with the wear that the wrong kappa accumulated (which the feature offset would then absorb).
    kappa_lifetime: bool = False
    #: degrees of freedom of the ln kappa prior (inf: normal). A prior fitted on n units is the Student-t
    #: predictive with n - 1 dof and scale std * sqrt(1 + 1/n) (set by ``hd.build_model``).
    log_kappa_df: float = float("inf")

    state_names = ("h", "log_kappa")
    health_index = 0
    increasing = True

    def __post_init__(self) -> None:
        _positive("h_fail", self.h_fail)
        if not (np.isfinite(self.offset_mean) and np.isfinite(self.offset_std) and self.offset_std >= 0):
            raise ValueError(f"ArchardWear: offset prior must be finite with std >= 0, got "
                             f"{self.offset_mean!r}, {self.offset_std!r}")
        if self.offset_mode not in ("rb", "state"):
            raise ValueError(f"ArchardWear.offset_mode must be 'rb' or 'state', got {self.offset_mode!r}")
        if self.offset_std > 0 and self.offset_mode == "rb":
            self.state_names = ("h", "log_kappa", "b", "P_b")
            self.param_mask = np.array([False, True, False, False])
        elif self.offset_std > 0:
            self.state_names = ("h", "log_kappa", "b")
            self.param_mask = np.array([False, True, False])
        else:
            self.param_mask = np.array([False, True])
        self.threshold = self.h_fail

    @property
    def has_offset(self) -> bool:
        return self.offset_std > 0

    @property
    def n_marginalised(self) -> int:
        """Columns holding an exact conditional posterior (not sampled): ``b`` and ``P_b`` in ``rb`` mode."""
        return 2 if (self.has_offset and self.offset_mode == "rb") else 0

    def observe(self, x):
        """Predictive mean and std of the feature per particle (offset included when modelled)."""
        if self.observe_fn is None:
            raise RuntimeError("ArchardWear has no observation model attached")
        mu, sd = self.observe_fn(x)
        if not self.has_offset:
            return mu, sd
        if self.offset_mode == "state":
            return mu + x[:, 2], sd
        return mu + x[:, 2], np.sqrt(sd * sd + x[:, 3])

    def params_moved(self, x_old_params: np.ndarray, x: np.ndarray) -> None:
        """Called by the filter after it jittered the parameter columns (in place): with
        ``kappa_lifetime`` the accumulated wear follows the new kappa (h - h0 scales with kappa)."""
        if self.kappa_lifetime:
            x[:, 0] = self.h0_mean + (x[:, 0] - self.h0_mean) * np.exp(x[:, 1] - x_old_params[:, 0])

    def assimilate(self, x: np.ndarray, z: float, mean: np.ndarray, std: np.ndarray,
                   robust_nu: float | None = None) -> None:
        """Kalman update (in place) of each particle's offset posterior ``(b, P_b)`` with observation ``z``.

        ``mean``/``std`` are :meth:`observe`'s predictive values for ``x``
        (so nothing is recomputed). With ``robust_nu`` (Student-t
        likelihood) the gain is down-weighted for outlying residuals
        (weight ``(nu + 1) / (nu + r^2)``, capped at 1), as an M-estimator.
        """
        if not (self.has_offset and self.offset_mode == "rb"):
            return
        P = x[:, 3]
        S = std * std
        innov = z - mean
        if robust_nu is not None:
            wgt = np.minimum((robust_nu + 1.0) / (robust_nu + innov * innov / S), 1.0)
            S = P + (S - P) / wgt  # measurement variance inflated by 1/weight
        K = P / S
        x[:, 2] += K * innov
        x[:, 3] = P * (1.0 - K)

    def propagate(self, x, u, rng):
        x = self.check_state(x)
        if isinstance(u, (int, float)):
            if not (np.isfinite(u) and u >= 0):
                raise ValueError(f"ArchardWear: the load-sliding integral W must be finite and >= 0, got {u!r}")
            W = float(u)
        else:
            W = np.asarray(u, dtype=float)
            if np.any(W < 0) or not np.all(np.isfinite(W)):
                raise ValueError("ArchardWear: the load-sliding integral W must be finite and >= 0")
        out = np.empty_like(x)
        if x.shape[1] > 2:
            out[:, 2:] = x[:, 2:]  # the feature offset (and its variance) is static
        if rng is not None:
            n = len(x)
            s = self.sigma_proc
            e = rng.standard_normal((2, n))
            # kappa W eps in one exp: exp(ln kappa + s e0 - s^2/2) W
            out[:, 0] = x[:, 0] + W * np.exp(x[:, 1] + (s * e[0] - 0.5 * s * s))
            out[:, 1] = x[:, 1] + self.sigma_log_kappa * e[1]
            if self.kappa_lifetime:
                out[:, 0] = self.h0_mean + (out[:, 0] - self.h0_mean) * np.exp(self.sigma_log_kappa * e[1])
        else:
            out[:, 0] = x[:, 0] + W * np.exp(x[:, 1])
            out[:, 1] = x[:, 1]
        return out

    def sample_prior(self, n, rng):
        h0 = np.abs(self.h0_mean + self.h0_std * rng.standard_normal(n))
        if np.isfinite(self.log_kappa_df):
            # posterior-predictive of an unseen unit from a few training units: Student-t tails reach
            # wear coefficients outside the (small-sample) training spread
            lk = self.log_kappa_mean + self.log_kappa_std * rng.standard_t(self.log_kappa_df, n)
        else:
            lk = self.log_kappa_mean + self.log_kappa_std * rng.standard_normal(n)
        if not self.has_offset:
            return np.column_stack([h0, lk])
        if self.offset_mode == "state":
            return np.column_stack([h0, lk, self.offset_mean + self.offset_std * rng.standard_normal(n)])
        return np.column_stack([h0, lk, np.full(n, self.offset_mean), np.full(n, self.offset_std**2)])

    def rul_fast(self, x: np.ndarray, future, step: float, max_steps: int, rng: np.random.Generator,
                 n_paths: int = 256, chunk: int = 256) -> np.ndarray | None:
        """RUL samples by shared exposure paths (exact per particle; used by ``rul_distribution``).

        In the forecast ``kappa`` is held at each particle's value (the random
        walk of ``log_kappa`` is an estimation device, not physics). Failure
        after j steps when ``kappa * U_j >= h_fail - h`` with ``U_j = sum W_k
        eps_k``; ``n_paths`` cumulative paths U are simulated once and each
        particle follows a random one, so the cost is ``n * steps``
        comparisons instead of ``n * steps`` model propagations. With
        ``h_fail_std > 0`` each particle draws its own failure threshold
        (the unit's failure wear is not known exactly). ``future``:
        scalar or history array to bootstrap (a callable returns None: use
        the generic stepper).
        """
        if callable(future):
            return None
        fut = np.asarray(future, float)
        n = len(x)
        thr = self.h_fail + (self.h_fail_std * rng.standard_normal(n) if self.h_fail_std > 0 else 0.0)
        D = (thr - x[:, 0]) / np.exp(x[:, 1])
        rul = np.full(n, np.inf)
        rul[D <= 0] = 0.0
        und = np.flatnonzero(D > 0)
        path = rng.integers(0, n_paths, len(und))
        carry = np.zeros(n_paths)
        s = self.sigma_proc
        v_mean = float(np.mean(fut)) if fut.size else 0.0
        if not np.isfinite(v_mean) or v_mean <= 0:
            return rul  # no exposure in the future: nothing fails
        done = 0
        while len(und) and done < max_steps:
            # chunk long enough for most particles to cross inside it
            need = int(np.ceil(1.3 * np.quantile(D[und], 0.95) / v_mean - done)) + 8
            c = int(min(max(need, 16), chunk if done else max(need, 16), max_steps - done))
            v = fut if fut.ndim == 0 else fut[rng.integers(0, fut.size, (c, n_paths))]
            # steps along axis 0 (contiguous rows: fast cumsum); float64 throughout
            inc = np.exp(s * rng.standard_normal((c, n_paths)) - 0.5 * s * s) * v
            U = (carry + np.cumsum(inc, axis=0)).T  # (n_paths, c)
            # one global searchsorted: row p offset by p * big keeps the flattened paths sorted
            big = 2.0 * (U[:, -1].max() + D[und].max() + 1.0)
            flat = np.ascontiguousarray(U + big * np.arange(n_paths)[:, None]).ravel()
            cnt = np.searchsorted(flat, D[und] + big * path, side="left") - path * c
            hit = cnt < c
            rul[und[hit]] = (done + cnt[hit] + 1) * step
            und, path = und[~hit], path[~hit]
            carry = U[:, -1]
            done += c
        return rul

    def process_cov(self, x_mean, u):
        dh = np.exp(x_mean[1]) * float(np.mean(u))
        var_h = dh * dh * (np.exp(self.sigma_proc**2) - 1.0)
        d = [var_h + 1e-30, self.sigma_log_kappa**2]
        if self.n_states > 2:
            d += [1e-12 * self.offset_std**2] + [0.0] * (self.n_states - 3)
        return np.diag(d)


@dataclass
class ExponentialFade(DegradationModel):
    """Capacity ``C`` [Ah] with exponential fade ``C_{k+1} = C_k exp(b dk) + w``.

    ``b`` [1/cycle, negative for fade] is augmented and follows a random walk
    (``sigma_b`` per cycle, scaled with sqrt(dk)) so curvature changes
    (accelerating fade) are absorbed; ``w ~ N(0, sigma_C^2 dk)``. Observation:
    measured capacity ~ N(C, sigma_obs^2). Failure when ``C <= C_eol``.

    Capacity regeneration (``regen_nu > 0``): after rest periods a Li-ion
    cell's measured capacity jumps *up* and decays back within a few cycles
    (a transient, not a reversal of the fade). The likelihood is then
    asymmetric: Gaussian for measurements below the modelled capacity,
    Student-t with ``regen_nu`` degrees of freedom above it (same scale, the
    density continuous at the mode), so upward jumps barely move the fade
    state or rate while a faster-than-modelled fade still counts fully.
    """

    C_eol: float = 1.4  # Ah
    C0_mean: float = 2.0  # Ah
    C0_std: float = 0.05  # Ah
    b_mean: float = -2e-3  # 1/cycle
    b_std: float = 2e-3  # 1/cycle
    sigma_C: float = 2e-3  # Ah / sqrt(cycle)
    sigma_b: float = 1e-4  # 1/cycle / sqrt(cycle)
    sigma_obs: float = 0.01  # Ah
    time_unit: str = "cycle"
    regen_nu: float = 0.0  # dof of the upper (regeneration) tail of the likelihood; 0 = symmetric

    state_names = ("C", "b")
    health_index = 0
    increasing = False

    def __post_init__(self) -> None:
        _positive("C_eol", self.C_eol)
        _positive("sigma_obs", self.sigma_obs)
        self.param_mask = np.array([False, True])
        self.threshold = self.C_eol
        self.observe_fn = self._observe

    def _observe(self, x):
        return x[:, 0], np.full(len(x), self.sigma_obs)

    @property
    def custom_likelihood(self) -> bool:
        """True when the filter must use :meth:`log_likelihood` (the asymmetric regeneration form)."""
        return self.regen_nu > 0

    def log_likelihood(self, z: float, x: np.ndarray) -> np.ndarray:
        """Asymmetric log-likelihood of measured capacity ``z`` per particle (up to a constant)."""
        r = (z - x[:, 0]) / self.sigma_obs
        nu = self.regen_nu
        return np.where(r <= 0, -0.5 * r * r, -0.5 * (nu + 1.0) * np.log1p(r * r / nu))

    def propagate(self, x, u, rng):
        x = self.check_state(x)
        dk = np.asarray(u, dtype=float)
        out = x.copy()
        out[:, 0] = x[:, 0] * np.exp(x[:, 1] * dk)
        if rng is not None:
            n = len(x)
            sq = np.sqrt(np.maximum(dk, 0.0))
            out[:, 0] += self.sigma_C * sq * rng.standard_normal(n)
            # reflected at 0: capacity fade does not reverse on average (regeneration is noise)
            out[:, 1] = -np.abs(x[:, 1] + self.sigma_b * sq * rng.standard_normal(n))
        return out

    def sample_prior(self, n, rng):
        C = self.C0_mean + self.C0_std * rng.standard_normal(n)
        b = -np.abs(self.b_mean + self.b_std * rng.standard_normal(n))
        return np.column_stack([C, b])

    def process_cov(self, x_mean, u):
        dk = float(np.mean(u))
        return np.diag([self.sigma_C**2 * dk + 1e-12, self.sigma_b**2 * dk + 1e-16])


@dataclass
class ParisCrack(DegradationModel):
    """Crack length ``a`` [m] under Paris' law ``da/dN = C' a^p``, ``p = m/2``.

    Exact integration over a step of ``dN`` cycles:
    ``a_{k+1}^{1-p} = a_k^{1-p} + (1-p) C' dN`` (p != 1), with a mean-one
    lognormal multiplier on ``C'`` per step (``sigma_proc``) as process noise
    and ``log C'`` random-walking (``sigma_logC`` per step). ``m`` is a
    material constant (fitted on training specimens). Observation: measured
    crack length ~ N(a, sigma_obs^2). Failure when ``a >= a_crit``.
    """

    a_crit: float = 49.8e-3  # m
    m: float = 3.0
    logC_mean: float = -20.0  # ln of C' in m^(1-p)/cycle
    logC_std: float = 0.3
    a0_mean: float = 9e-3  # m
    a0_std: float = 0.1e-3  # m
    sigma_proc: float = 0.05
    sigma_logC: float = 0.02
    sigma_obs: float = 0.2e-3  # m
    time_unit: str = "cycle"

    state_names = ("a", "log_C")
    health_index = 0
    increasing = True

    def __post_init__(self) -> None:
        _positive("a_crit", self.a_crit)
        _positive("m", self.m)
        if abs(self.m - 2.0) < 1e-9:
            raise ValueError("ParisCrack: m = 2 (p = 1) needs the exponential form; use m != 2")
        self.param_mask = np.array([False, True])
        self.threshold = self.a_crit
        self.observe_fn = self._observe

    def _observe(self, x):
        return x[:, 0], np.full(len(x), self.sigma_obs)

    def grow(self, a: np.ndarray, logC: np.ndarray, dN) -> np.ndarray:
        """Closed-form Paris integration; returns inf once the crack is unstable (p > 1)."""
        p = 0.5 * self.m
        q = 1.0 - p
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            base = np.power(np.maximum(a, 1e-12), q) + q * np.exp(logC) * dN
            a_new = np.where(base > 0, np.power(np.maximum(base, 1e-300), 1.0 / q), np.inf)
        return a_new

    def propagate(self, x, u, rng):
        x = self.check_state(x)
        dN = np.asarray(u, dtype=float)
        out = x.copy()
        logC = x[:, 1]
        if rng is not None:
            n = len(x)
            s = self.sigma_proc
            logC_step = logC + s * rng.standard_normal(n) - 0.5 * s * s
            out[:, 1] = logC + self.sigma_logC * rng.standard_normal(n)
        else:
            logC_step = logC
        out[:, 0] = self.grow(x[:, 0], logC_step, dN)
        return out

    def sample_prior(self, n, rng):
        a = self.a0_mean + self.a0_std * rng.standard_normal(n)
        lc = self.logC_mean + self.logC_std * rng.standard_normal(n)
        return np.column_stack([np.maximum(a, 1e-6), lc])

    def process_cov(self, x_mean, u):
        a1 = self.grow(np.array([x_mean[0]]), np.array([x_mean[1]]), float(np.mean(u)))[0]
        da = a1 - x_mean[0]
        return np.diag([(self.sigma_proc * da) ** 2 + 1e-14, self.sigma_logC**2])


MODELS = {"archard": ArchardWear, "exponential_fade": ExponentialFade, "paris": ParisCrack}

__all__ = ["DegradationModel", "ArchardWear", "ExponentialFade", "ParisCrack", "MODELS"]
