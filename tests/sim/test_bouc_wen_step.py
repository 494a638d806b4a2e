"""The Bouc-Wen hysteresis step (kernel.bouc_wen_step, effect parameter hysteresis.exact_step).

Regression: ``hdphm sim fleet --family hysteretic-robot --seed 21 --actuators 6 --missions 150 --duration 6
--set mission_hours=600`` stopped with "plant diverged at sample 2682": unit EMA-0000, mission 5, once wear
had opened a backlash gap (h+ + h- > 2 delta_0). Inside the gap the mesh no longer damps the flexspline's
tangential mode, and the explicit Euler step of z_h (taken with y_FS' from the same old state) is a
forward-Euler oscillator on the unloading branch; the flexspline rang up, z_h left +-z_max and overflowed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hd_sim import EffectSet, sample_population, simulate_mission
from hd_sim.families import family_unit
from hd_sim.kernel import bouc_wen_step

# the failing mission: EMA-0000 of the seed-21 fleet, mission 5 (its mission seed and the health the
# life had reached after missions 0-4 at mission_hours = 600, as simulate_life computed them)
SEED21_MISSION5 = dict(profile="inspection", seed=1375548704, duration=6.0, mission_index=5,
                       health={"h_plus": 3.4196147489226188e-06, "h_minus": 2.76445095447314e-06})


@pytest.fixture(scope="module")
def seed21_unit():
    return family_unit("hysteretic-robot", sample_population(1, 21)[0], EffectSet.default(), 21)


def _run(unit, effects=None, n_sub=None):
    c = SEED21_MISSION5
    return simulate_mission(unit.params, effects or unit.effects, c["profile"], c["seed"], duration=c["duration"],
                            fs=unit.fs, health=c["health"], mission_index=c["mission_index"], n_sub=n_sub)


def test_seed21_hysteretic_robot_mission_stays_finite_and_converged(seed21_unit):
    u = seed21_unit
    assert u.fs == 1000.0 and u.effects.p("hysteresis", "exact_step") == 1.0
    _, tr = _run(u)
    eff = tr["effects"]["params"]
    assert eff["backlash_j"] > 0  # the case runs with the mesh gap open (what triggered the divergence)
    I = tr["internal"]
    # Bouc-Wen with beta = gamma never leaves +-z_max = A/(beta + gamma) when started inside it
    assert np.max(np.abs(I["z_h"])) <= eff["z_max"] * (1 + 1e-9)
    # the same mission at a 4x finer step (dt 6.25 us): the 25 us result is converged, not just finite
    _, fine = _run(u, n_sub=160)
    F = fine["internal"]
    rel = lambda k: math.sqrt(np.mean((I[k] - F[k]) ** 2) / np.mean(F[k] ** 2))  # noqa: E731
    assert rel("Q_red") < 0.01 and rel("F_my") < 0.01
    assert np.max(np.abs(I["y_FS_d"])) < 1.1 * np.max(np.abs(F["y_FS_d"]))


def test_seed21_case_diverges_with_the_explicit_step(seed21_unit):
    """The case above exercises the instability: the old explicit step (still the default plant's) fails on it."""
    old = seed21_unit.effects.with_params(**{"hysteresis.exact_step": 0.0})
    with pytest.raises(FloatingPointError, match="diverged"):
        _run(seed21_unit, old)


def _reference(z0, v, A, beta, gamma, dt):
    from scipy.integrate import solve_ivp

    f = lambda t, z: [A * v - beta * abs(v) * z[0] - gamma * v * abs(z[0])]  # noqa: E731
    return solve_ivp(f, (0.0, dt), [z0], method="LSODA", rtol=1e-11, atol=1e-9 * A / (beta + gamma)).y[0, -1]


@pytest.mark.parametrize("z0, v, dt", [
    (0.0, 0.01, 25e-6),       # loading from rest
    (4000.0, 0.2, 25e-6),     # loading near saturation at a speed where Euler overshoots ((beta+gamma)|v|dt = 2.1)
    (4000.0, -0.05, 25e-6),   # unloading, stays positive
    (300.0, -0.05, 25e-6),    # unloading through 0 within the step, then loading the other way
    (-4900.0, 3.0, 25e-6),    # a hard reversal far beyond the explicit step's limit
    (1234.0, 0.0, 25e-6),     # held
])
def test_bouc_wen_step_is_exact_for_a_held_speed(z0, v, dt):
    A, beta = 2.1e9, 2.1e5  # the seed-21 unit's values (A_ratio 4, z_max = A/(2 beta) = 5000 N)
    for gamma in (beta, 0.5 * beta):
        z = bouc_wen_step(z0, v, A, beta, gamma, dt)
        assert z == pytest.approx(_reference(z0, v, A, beta, gamma, dt), rel=1e-7, abs=1e-6 * A / (beta + gamma))
        assert abs(z) <= max(abs(z0), A / (beta + gamma)) * (1 + 1e-12)
    # the explicit Euler step it replaces leaves the bound at the fast cases
    if abs(v) * 2 * beta * dt > 2:
        z_euler = z0 + dt * (A * v - beta * abs(v) * z0 - beta * v * abs(z0))
        assert abs(z_euler) > A / (2 * beta)
