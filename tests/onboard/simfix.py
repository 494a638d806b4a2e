"""Missions from the real plant simulator (hd_sim) for the onboard and ROS tests.

hd_sim keeps health constant within a mission, so a fault **injected mid-mission**
is built here (never in hd_sim) by splicing two simulations that share
actuator, profile, gusts and sensor-noise seeds and differ only in the fault:
samples before ``t_fault`` come from the healthy run, samples from ``t_fault``
on from the faulted run. The plant state jumps at ``t_fault`` to the faulted
trajectory, i.e. a sudden fault onset (a grease loss, a flexspline crack).
"""
from __future__ import annotations

import dataclasses

import numpy as np

SIGNALS = ("t", "theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")


def sim_mission(actuator: int = 0, seed: int = 0, duration: float = 20.0, pop_seed: int = 7, effects=None,
                mission_index: int = 0, profile: str = "inspection", t0_ns: int = 1_700_000_000_000_000_000):
    """One simulated mission (default realistic effects) of unit ``actuator`` of a population; t0_ns set."""
    from hd_sim import EffectSet, sample_population, simulate_mission

    p = sample_population(actuator + 1, seed=pop_seed)[actuator]
    m, _ = simulate_mission(p, effects if effects is not None else EffectSet.default(), profile, seed,
                            duration=duration, mission_index=mission_index)
    return dataclasses.replace(m, t0_ns=t0_ns)


def faulted_mission(t_fault: float, effect: str = "lubrication_loss", param: str = "severity=3.0",
                    actuator: int = 0, seed: int = 0, duration: float = 20.0, **kw):
    """Healthy before ``t_fault`` [s], ``effect`` with ``param`` from then on (see module docstring)."""
    from hd_sim import EffectSet

    a = sim_mission(actuator, seed, duration, **kw)
    b = sim_mission(actuator, seed, duration, effects=EffectSet.default().apply_cli([f"{effect}=on"], [f"{effect}.{param}"]), **kw)
    ka, kb = a.t < t_fault, b.t >= t_fault
    f = {nm: np.concatenate([getattr(a, nm)[ka], getattr(b, nm)[kb]]) for nm in SIGNALS}
    return dataclasses.replace(a, **f)
