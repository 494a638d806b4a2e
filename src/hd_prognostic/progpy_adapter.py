"""Our Archard model as a progpy ``PrognosticsModel``, to run progpy's particle filter as a baseline.

progpy's PF adds Gaussian, homoscedastic measurement noise and resamples
(residual) at every step; the process noise is drawn inside ``next_state``
exactly as :meth:`ArchardWear.propagate` does (multiplicative lognormal wear
increment, random-walk ``log_kappa``), so both filters run the same
stochastic model. The observation std handed to progpy is the model's std at
a reference wear (progpy cannot take a state-dependent std).
"""

from __future__ import annotations

import numpy as np

from hd_prognostic.models import ArchardWear


def make_progpy_model(model: ArchardWear, seed: int = 0):
    """A vectorised progpy ``PrognosticsModel`` equivalent to ``model`` (inputs W [J] per unit time)."""
    from progpy import PrognosticsModel

    rng = np.random.default_rng(seed)
    obs = model.observe_fn

    class ArchardProgpy(PrognosticsModel):
        inputs = ["W"]
        states = ["h", "log_kappa"]
        outputs = ["y"]
        events = ["EOL"]
        is_vectorized = True
        default_parameters = {"x0": {"h": 0.0, "log_kappa": model.log_kappa_mean},
                              "process_noise": {"h": 0.0, "log_kappa": 0.0}}

        def next_state(self, x, u, dt):
            h = np.atleast_1d(np.asarray(x["h"], float))
            lk = np.atleast_1d(np.asarray(x["log_kappa"], float))
            X = model.propagate(np.column_stack([h, lk]), float(u["W"]) * dt, rng)
            return self.StateContainer({"h": X[:, 0], "log_kappa": X[:, 1]})

        def output(self, x):
            h = np.atleast_1d(np.asarray(x["h"], float))
            mu, _ = obs(np.column_stack([h, np.zeros_like(h)]))
            return self.OutputContainer({"y": mu if mu.size > 1 else float(mu[0])})

        def event_state(self, x):
            return {"EOL": np.maximum(1.0 - np.asarray(x["h"]) / model.h_fail, 0.0)}

        def threshold_met(self, x):
            return {"EOL": np.asarray(x["h"]) >= model.h_fail}

    return ArchardProgpy()


def make_progpy_pf(model: ArchardWear, particles: np.ndarray, obs_std: float, seed: int = 0):
    """progpy ``ParticleFilter`` on the equivalent model, started from our prior particles."""
    from progpy.state_estimators import ParticleFilter as ProgpyPF
    from progpy.uncertain_data import UnweightedSamples

    pm = make_progpy_model(model, seed)
    x0 = UnweightedSamples([{"h": float(a), "log_kappa": float(b)} for a, b in particles])
    return ProgpyPF(pm, x0, num_particles=len(particles), measurement_noise={"y": float(obs_std)}, dt=1.0), pm
